// Fast DDS stand-in for a ROS 2 robot (rmw_fastrtps_cpp) publishing
// diagnostic_msgs/DiagnosticArray on loopback. Used by the integration tests.
//
// Usage: publisher --domain D --topic rt/<ns>/diagnostics_agg --rate HZ [--count N]
//                  --status 'LEVEL|NAME|MESSAGE|HARDWARE_ID|k1=v1;k2=v2' [--status ...]
//        publisher --domain D --topic rt/<ns>/diagnostics_agg --rate HZ [--count N]
//                  --raw-hex HEX [--raw-hex HEX ...]
//
// With --status, publishes one DiagnosticArray_ holding those statuses every period.
// With --raw-hex (exclusive with --status), publishes the given bytes verbatim as the
// serialized payload, cycling through them one per period. HEX includes the 4-byte
// encapsulation header (e.g. "00010000..." for CDR little-endian); whitespace is
// ignored. Nothing is validated, so truncated or malformed payloads go out as given,
// under the same type name "diagnostic_msgs::msg::dds_::DiagnosticArray_". Note that
// Fast DDS pads the DATA submessage to a multiple of 4 bytes with zeros, so a
// reader may see up to 3 extra zero bytes after a payload whose length is not a
// multiple of 4 (and a payload shorter than 4 bytes arrives as 4). Cyclone DDS drops
// an undecodable payload silently; one with an unknown encapsulation identifier
// (e.g. 00ff) makes it discard the whole RTPS message, which stalls the reliable
// stream until the sample leaves this writer's history (KEEP_LAST 10).
//
// With --interface ADDRESS, DDS runs on that IPv4 address only with Fast DDS's default
// discovery (the multicast initial peer), as on a robot of a network without multicast;
// without it, on 127.0.0.1 with unicast discovery.
//
// Prints "ready" once the writer exists and "matched N" whenever the number of
// matched readers changes. Runs until N samples are sent (0 = forever, the
// default), or SIGINT/SIGTERM.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <functional>
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
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include "diagnosticsPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using eprosima::fastdds::rtps::UDPv4TransportDescriptor;
using eprosima::fastrtps::rtps::IPLocator;
using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::Locator_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;
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

using RawPayload = std::vector<uint8_t>;

// Hex digits (whitespace ignored) to bytes.
RawPayload parse_hex(const std::string& text)
{
    std::string digits;
    for (char c : text) {
        if (std::isspace(static_cast<unsigned char>(c))) {
            continue;
        }
        if (!std::isxdigit(static_cast<unsigned char>(c))) {
            throw std::invalid_argument("bad --raw-hex (not a hex digit '" + std::string(1, c) + "'): " + text);
        }
        digits.push_back(c);
    }
    if (digits.empty() || digits.size() % 2 != 0) {
        throw std::invalid_argument("bad --raw-hex (want a non-empty, even number of hex digits): " + text);
    }
    RawPayload bytes;
    bytes.reserve(digits.size() / 2);
    for (std::size_t i = 0; i < digits.size(); i += 2) {
        bytes.push_back(static_cast<uint8_t>(std::stoul(digits.substr(i, 2), nullptr, 16)));
    }
    return bytes;
}

// Type support that sends a RawPayload (std::vector<uint8_t>) verbatim as the serialized
// payload, under the DiagnosticArray_ type name so it matches the same readers.
// In Fast DDS 2.9 serialize() writes the 4-byte encapsulation header into payload->data
// itself (see the generated diagnosticsPubSubTypes.cxx), so the raw bytes carry their own
// header; payload->encapsulation is set from it for consistency. Unkeyed, like the real type.
class RawPayloadType : public TopicDataType {
public:
    explicit RawPayloadType(uint32_t max_size)
    {
        setName("diagnostic_msgs::msg::dds_::DiagnosticArray_");
        m_typeSize = max_size;
        m_isGetKeyDefined = false;
        auto_fill_type_object(false);
        auto_fill_type_information(false);
    }

    bool serialize(void* data, SerializedPayload_t* payload) override
    {
        const RawPayload& bytes = *static_cast<const RawPayload*>(data);
        if (bytes.size() > payload->max_size) {
            return false;
        }
        if (!bytes.empty()) {
            std::memcpy(payload->data, bytes.data(), bytes.size());
        }
        payload->length = static_cast<uint32_t>(bytes.size());
        payload->encapsulation = bytes.size() >= 2
            ? static_cast<uint16_t>((static_cast<uint16_t>(bytes[0]) << 8) | bytes[1])
            : static_cast<uint16_t>(CDR_BE);
        return true;
    }

    bool deserialize(SerializedPayload_t* payload, void* data) override
    {
        RawPayload& bytes = *static_cast<RawPayload*>(data);
        bytes.assign(payload->data, payload->data + payload->length);
        return true;
    }

    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        const auto size = static_cast<uint32_t>(static_cast<const RawPayload*>(data)->size());
        return [size]() -> uint32_t { return size; };
    }

    void* createData() override { return new RawPayload(); }

    void deleteData(void* data) override { delete static_cast<RawPayload*>(data); }

    bool getKey(void*, InstanceHandle_t*, bool) override { return false; }
};

struct Options {
    DomainId_t domain = 0;
    std::string topic;
    double rate = 1.0;
    long count = 0;  // 0 = forever
    std::vector<diag::DiagnosticStatus_> statuses;
    std::vector<RawPayload> raw_payloads;
    std::string interface;  // empty: loopback
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
        } else if (arg == "--raw-hex") {
            opt.raw_payloads.push_back(parse_hex(value));
        } else if (arg == "--interface") {
            opt.interface = value;
        } else {
            throw std::invalid_argument("unknown argument: " + arg);
        }
    }
    if (opt.topic.empty() || opt.rate <= 0 || opt.count < 0) {
        throw std::invalid_argument("--topic and a positive --rate are required");
    }
    if (!opt.statuses.empty() && !opt.raw_payloads.empty()) {
        throw std::invalid_argument("--status and --raw-hex are mutually exclusive");
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

DomainParticipantQos interface_participant_qos(const std::string& address)
{
    DomainParticipantQos qos;
    qos.name("overseer_test_publisher");
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.emplace_back(address);
    qos.transport().user_transports.push_back(udp);
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
                  << "[--count N] --status 'LEVEL|NAME|MESSAGE|HARDWARE_ID|k=v;...' [--status ...]\n"
                  << "       publisher --domain D --topic T --rate HZ [--count N] --raw-hex HEX [--raw-hex ...]\n";
        return 2;
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);

    auto* factory = DomainParticipantFactory::get_instance();
    DomainParticipant* participant = factory->create_participant(
        opt.domain, opt.interface.empty() ? loopback_participant_qos() : interface_participant_qos(opt.interface));
    if (participant == nullptr) {
        std::cerr << "publisher: cannot create participant\n";
        return 1;
    }
    const bool raw = !opt.raw_payloads.empty();
    TypeSupport type;
    if (raw) {
        std::size_t max_size = 0;
        for (const RawPayload& bytes : opt.raw_payloads) {
            max_size = std::max(max_size, bytes.size());
        }
        type = TypeSupport(new RawPayloadType(static_cast<uint32_t>(max_size)));
    } else {
        type = TypeSupport(new diag::DiagnosticArray_PubSubType());
    }
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
        bool ok = false;
        if (raw) {
            ok = writer->write(&opt.raw_payloads[static_cast<std::size_t>(sent) % opt.raw_payloads.size()]);
        } else {
            auto since_epoch = std::chrono::system_clock::now().time_since_epoch();
            auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(since_epoch).count();
            msg.header().stamp().sec(static_cast<int32_t>(ns / 1000000000));
            msg.header().stamp().nanosec(static_cast<uint32_t>(ns % 1000000000));
            ok = writer->write(&msg);
        }
        if (!ok) {
            std::cerr << "publisher: write " << sent << " failed\n";
        }
        next += period;
    }

    writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(1, 0));
    participant->delete_contained_entities();
    factory->delete_participant(participant);
    return 0;
}
