// Fast DDS stand-in for a ROS 2 robot (rmw_fastrtps_cpp) publishing
// diagnostic_msgs/DiagnosticArray on loopback. Used by the integration tests.
//
// Usage: publisher --domain D --topic rt/<ns>/diagnostics_agg --rate HZ [--count N]
//                  --status 'LEVEL|NAME|MESSAGE|HARDWARE_ID|k1=v1;k2=v2' [--status ...]
//
// Prints "ready" once the writer exists and "matched N" whenever the number of
// matched readers changes. Runs until N samples are sent, or SIGINT/SIGTERM.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include "diagnosticsPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using eprosima::fastdds::rtps::UDPv4TransportDescriptor;
using eprosima::fastrtps::rtps::IPLocator;
using eprosima::fastrtps::rtps::Locator_t;
namespace diag = diagnostic_msgs::msg::dds_;

namespace {

// Same bound as Cyclone's MaxAutoParticipantIndex in the tests' configuration.
constexpr uint32_t kMaxParticipantIndex = 60;

std::atomic<bool> g_stop{false};
std::mutex g_out_mutex;

void on_signal(int) { g_stop = true; }

void say(const std::string& line)
{
    std::lock_guard<std::mutex> lock(g_out_mutex);
    std::cout << line << std::endl;  // endl flushes
}

// Sleeps in short slices so a signal ends the wait; false if we must stop.
bool sleep_until(std::chrono::steady_clock::time_point deadline)
{
    while (!g_stop && std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(
            deadline - std::chrono::steady_clock::now(), std::chrono::milliseconds(50)));
    }
    return !g_stop;
}

// Whole-string number parsing with a readable error (std::stol alone says "stol").
template <typename T>
T parse_number(const std::string& what, const std::string& text)
{
    std::istringstream stream(text);
    T value{};
    if (!(stream >> value) || !stream.eof()) {
        throw std::invalid_argument("bad " + what + ": '" + text + "'");
    }
    return value;
}

std::vector<std::string> split(const std::string& text, char sep)
{
    std::vector<std::string> parts;
    std::string part;
    std::istringstream stream(text);
    while (std::getline(stream, part, sep)) {
        parts.push_back(part);
    }
    if (!text.empty() && text.back() == sep) {
        parts.emplace_back();
    }
    return parts;
}

diag::DiagnosticStatus_ parse_status(const std::string& spec)
{
    std::vector<std::string> f = split(spec, '|');
    if (f.size() < 4 || f.size() > 5) {
        throw std::invalid_argument("bad --status (want LEVEL|NAME|MESSAGE|HARDWARE_ID[|k=v;...]): " + spec);
    }
    int level = parse_number<int>("level", f[0]);
    if (level < 0 || level > 255) {
        throw std::invalid_argument("level out of range: " + f[0]);
    }
    diag::DiagnosticStatus_ status;
    status.level(static_cast<uint8_t>(level));
    status.name(f[1]);
    status.message(f[2]);
    status.hardware_id(f[3]);
    if (f.size() == 5 && !f[4].empty()) {
        for (const std::string& pair : split(f[4], ';')) {
            auto eq = pair.find('=');
            if (eq == std::string::npos) {
                throw std::invalid_argument("bad key=value: " + pair);
            }
            diag::KeyValue_ kv;
            kv.key(pair.substr(0, eq));
            kv.value(pair.substr(eq + 1));
            status.values().push_back(kv);
        }
    }
    return status;
}

struct Options {
    DomainId_t domain = 0;
    std::string topic;
    double rate = 1.0;
    long count = 0;  // 0 = forever
    std::vector<diag::DiagnosticStatus_> statuses;
};

Options parse_args(int argc, char** argv)
{
    Options opt;
    for (int i = 1; i < argc; ++i) {
        std::string arg = argv[i];
        if (i + 1 >= argc) {
            throw std::invalid_argument("missing value for " + arg);
        }
        std::string value = argv[++i];
        if (arg == "--domain") {
            opt.domain = parse_number<DomainId_t>(arg, value);
        } else if (arg == "--topic") {
            opt.topic = value;
        } else if (arg == "--rate") {
            opt.rate = parse_number<double>(arg, value);
        } else if (arg == "--count") {
            opt.count = parse_number<long>(arg, value);
        } else if (arg == "--status") {
            opt.statuses.push_back(parse_status(value));
        } else {
            throw std::invalid_argument("unknown argument: " + arg);
        }
    }
    if (opt.topic.empty() || opt.rate <= 0 || opt.count < 0) {
        throw std::invalid_argument("--topic and a positive --rate are required");
    }
    return opt;
}

class MatchListener : public DataWriterListener {
public:
    void on_publication_matched(DataWriter*, const PublicationMatchedStatus& info) override
    {
        if (info.current_count_change != 0) {
            say("matched " + std::to_string(info.current_count));
        }
    }
};

DomainParticipantQos loopback_participant_qos()
{
    DomainParticipantQos qos;
    qos.name("overseer_test_publisher");
    // No shared memory: UDP on 127.0.0.1 only, so Cyclone DDS can see us.
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.emplace_back("127.0.0.1");
    udp->maxInitialPeersRange = kMaxParticipantIndex + 1;
    qos.transport().user_transports.push_back(udp);
    // Unicast discovery: port 0 means "every participant index in range".
    Locator_t peer;
    IPLocator::setIPv4(peer, "127.0.0.1");
    qos.wire_protocol().builtin.initialPeersList.push_back(peer);
    return qos;
}

}  // namespace

int main(int argc, char** argv)
{
    Options opt;
    try {
        opt = parse_args(argc, argv);
    } catch (const std::exception& e) {
        std::cerr << "publisher: " << e.what() << "\nusage: publisher --domain D --topic T --rate HZ "
                  << "[--count N] --status 'LEVEL|NAME|MESSAGE|HARDWARE_ID|k=v;...' [--status ...]\n";
        return 2;
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);

    auto* factory = DomainParticipantFactory::get_instance();
    DomainParticipant* participant = factory->create_participant(opt.domain, loopback_participant_qos());
    if (participant == nullptr) {
        std::cerr << "publisher: cannot create participant\n";
        return 1;
    }
    TypeSupport type(new diag::DiagnosticArray_PubSubType());
    type.register_type(participant);
    Topic* topic = participant->create_topic(opt.topic, type.get_type_name(), TOPIC_QOS_DEFAULT);
    Publisher* publisher = participant->create_publisher(PUBLISHER_QOS_DEFAULT);

    DataWriterQos wqos = DATAWRITER_QOS_DEFAULT;
    wqos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    wqos.durability().kind = VOLATILE_DURABILITY_QOS;  // Fast DDS defaults to TRANSIENT_LOCAL
    wqos.history().kind = KEEP_LAST_HISTORY_QOS;
    wqos.history().depth = 10;
    MatchListener listener;
    DataWriter* writer = topic && publisher ? publisher->create_datawriter(topic, wqos, &listener) : nullptr;
    if (writer == nullptr) {
        std::cerr << "publisher: cannot create data writer\n";
        participant->delete_contained_entities();
        factory->delete_participant(participant);
        return 1;
    }
    say("ready");

    diag::DiagnosticArray_ msg;
    msg.status(opt.statuses);
    const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(1.0 / opt.rate));
    auto next = std::chrono::steady_clock::now();
    for (long sent = 0; (opt.count == 0 || sent < opt.count) && sleep_until(next); ++sent) {
        auto since_epoch = std::chrono::system_clock::now().time_since_epoch();
        auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(since_epoch).count();
        msg.header().stamp().sec(static_cast<int32_t>(ns / 1000000000));
        msg.header().stamp().nanosec(static_cast<uint32_t>(ns % 1000000000));
        writer->write(&msg);
        next += period;
    }

    writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(1, 0));
    participant->delete_contained_entities();
    factory->delete_participant(participant);
    return 0;
}
