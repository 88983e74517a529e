"""The verdict on a robot (what the check and the Icinga 2 push say) and the check's reading of the API.

Pure functions: no exporter, no network.
"""

from __future__ import annotations

import re

import pytest

from overseer.check.document import CheckError, robot_from_document
from overseer.verdict import (
    CRITICAL,
    OK,
    UNKNOWN,
    WARNING,
    ReportedComponent,
    ReportedRobot,
    Settings,
    parse_number,
    perf_label,
    perf_number,
    perfdata,
    plugin_output,
    state_of,
    summary,
    worst_state,
)
from overseer.verdict import judge as judge_verdict


def judge(robot: ReportedRobot, settings: Settings) -> tuple[int, str]:
    """The exit state and what the check prints for `robot`."""
    verdict = judge_verdict(robot, settings)
    return verdict.state, plugin_output(verdict, settings.verbosity)


def component(
    name: str, level: int = 0, message: str = "OK", hardware_id: str = "", **values: str
) -> ReportedComponent:
    """A component with key-values given as keyword arguments."""
    return ReportedComponent(name, hardware_id, level, message, list(values.items()))


def robot(
    *components: ReportedComponent, up: bool = True, last_message: float | None = 100.0
) -> ReportedRobot:
    """robot1 with `components`, as of time 112."""
    return ReportedRobot("robot1", up, last_message, 112.0, list(components))


def test_worst_state_ranks_critical_over_warning_over_unknown_over_ok() -> None:
    assert worst_state([OK, UNKNOWN, WARNING]) == WARNING
    assert worst_state([UNKNOWN, CRITICAL, WARNING]) == CRITICAL
    assert worst_state([OK, UNKNOWN]) == UNKNOWN
    assert worst_state([]) == OK


@pytest.mark.parametrize(
    ("level", "stale_state", "expected"),
    [
        (0, UNKNOWN, OK),
        (1, CRITICAL, WARNING),
        (2, UNKNOWN, CRITICAL),
        (3, UNKNOWN, UNKNOWN),
        (3, WARNING, WARNING),
        (3, CRITICAL, CRITICAL),
    ],
)
def test_levels_map_to_nagios_states_and_stale_follows_stale_state(
    level: int, stale_state: int, expected: int
) -> None:
    assert state_of(component("/A", level), stale_state) == expected


def test_warning_beats_a_stale_component() -> None:
    state, output = judge(
        robot(component("/A", 3, "Charge OK"), component("/B", 1, "Low charge")), Settings()
    )
    assert state == WARNING
    assert output.splitlines()[0].startswith("WARNING - robot1: /B (Low charge) (also 1 UNKNOWN) |")


def test_stale_state_critical_makes_a_stale_component_critical() -> None:
    state, output = judge(
        robot(component("/A", 3, "Charge OK"), component("/B", 1)), Settings(stale_state=CRITICAL)
    )
    assert state == CRITICAL
    assert "CRITICAL (stale) sensor(s) list:\n/A: Charge OK" in output


def test_output_has_status_line_perfdata_and_the_papers_lists() -> None:
    components = (
        component("/Power", 1, "Warning"),
        component("/Power/Laptop Battery", 1, "Low charge", "power2"),
        component("/Power/Robot Battery", 0, "Charge OK", "power1"),
        component("/Laser", 2, "Error"),
        component("/Laser/Laser2", 2, "No scans received", "laser2"),
        component("/Temp/Sensor1", 3, "Normal", "temp1"),
    )
    state, output = judge(robot(*components), Settings())
    assert state == CRITICAL
    assert output == (
        "CRITICAL - robot1: /Laser/Laser2 (No scans received), /Laser (Error) (also 2 WARNING, 1 UNKNOWN)"
        " | 'error'=2;;;0 'warn'=2;;;0 'stale'=1;;;0 'ok'=1;;;0\n"
        "CRITICAL sensor(s) list:\n"
        "/Laser: Error\n"
        "/Laser/Laser2 [laser2]: No scans received\n"
        "WARNING sensor(s) list:\n"
        "/Power: Warning\n"
        "/Power/Laptop Battery [power2]: Low charge\n"
        "UNKNOWN (stale) sensor(s) list:\n"
        "/Temp/Sensor1 [temp1]: Normal\n"
        "OK sensor(s) list:\n"
        "/Power/Robot Battery [power1]: Charge OK"
    )


def test_all_ok_says_how_many_components() -> None:
    state, output = judge(robot(component("/A"), component("/B")), Settings())
    assert (state, output.splitlines()[0]) == (
        OK,
        "OK - robot1: 2 components OK | 'error'=0;;;0 'warn'=0;;;0 'stale'=0;;;0 'ok'=2;;;0",
    )


def test_status_line_names_three_components_then_counts_the_rest() -> None:
    components = [component(f"/C{index}", 2, f"fault {index}") for index in range(5)]
    text = summary(components, [CRITICAL] * 5, CRITICAL)
    assert text == "/C0 (fault 0), /C1 (fault 1), /C2 (fault 2) and 2 more"


def test_status_line_cuts_long_messages_and_marks_stale_ones() -> None:
    long = component("/A", 2, "x" * 100)
    stale = component("/B", 3, "Normal")
    assert summary([long], [CRITICAL], CRITICAL) == f"/A ({'x' * 57}...)"
    assert summary([stale], [UNKNOWN], UNKNOWN) == "/B (stale: Normal)"


def test_name_filter_is_a_case_insensitive_substring() -> None:
    components = (component("/Power/Robot Battery", 1, "Low"), component("/Laser/Laser2", 2, "No scans"))
    state, output = judge(robot(*components), Settings(name="BATTERY"))
    assert state == WARNING
    assert "Laser" not in output


def test_name_regex_and_name_must_both_match() -> None:
    components = (component("/Motor/Motor1", 1), component("/Motor/Motor2", 2), component("/Temp/Sensor1", 2))
    state, output = judge(robot(*components), Settings(name="motor", name_regex=re.compile(r"1$")))
    assert state == WARNING
    assert "'warn'=1;;;0" in output
    assert "Motor2" not in output


def test_filter_matching_nothing_is_unknown_not_critical() -> None:
    state, output = judge(robot(component("/Laser/Laser2", 2)), Settings(name="battery"))
    assert (state, output) == (
        UNKNOWN,
        "UNKNOWN - robot1: no component with name containing 'battery' among its 1 components",
    )


def test_a_filter_with_a_pipe_cannot_break_the_output() -> None:
    state, output = judge(robot(component("/Laser/Laser2", 2)), Settings(name_regex=re.compile("Temp|Motor")))
    assert (state, output) == (
        UNKNOWN,
        "UNKNOWN - robot1: no component with name matching /Temp¦Motor/ among its 1 components",
    )


def test_robot_without_components_is_unknown() -> None:
    assert judge(robot(), Settings()) == (UNKNOWN, "UNKNOWN - robot1: the robot reports no components")


def test_robot_down_has_its_own_message() -> None:
    assert judge(robot(component("/A", 3), up=False), Settings()) == (
        UNKNOWN,
        "UNKNOWN - robot1 is down: no diagnostics received for 12 s",
    )


def test_robot_never_heard_from_is_down_with_its_own_message() -> None:
    state, output = judge(robot(up=False, last_message=None), Settings(stale_state=CRITICAL))
    assert state == CRITICAL
    assert output == "CRITICAL - robot1 is down: the exporter knows it but never received its diagnostics"


def test_pipes_and_newlines_in_messages_cannot_break_the_output() -> None:
    _, output = judge(robot(component("/A|B", 1, "first line\nsecond | third")), Settings())
    first_line, *long_output = output.splitlines()
    assert first_line.count("|") == 1
    assert long_output == ["WARNING sensor(s) list:", "/A¦B: first line second ¦ third"]


def test_verbose_lists_key_values() -> None:
    _, output = judge(
        robot(component("/Power/Robot Battery", 0, "Charge OK", voltage="12.70")), Settings(verbosity=1)
    )
    assert output.splitlines()[-1] == "/Power/Robot Battery: Charge OK (voltage=12.70)"


def test_perfdata_values_adds_numeric_key_values_only() -> None:
    battery = component(
        "/Power/Robot Battery", 0, "OK", "power1", voltage="12.70", state="charging", nan="nan"
    )
    assert perfdata([battery], with_values=True) == [
        "'error'=0;;;0",
        "'warn'=0;;;0",
        "'stale'=0;;;0",
        "'ok'=1;;;0",
        "'/Power/Robot Battery[power1]:voltage'=12.7;;;;",
    ]
    assert len(perfdata([battery], with_values=False)) == 4


def test_the_verdict_is_data_its_sections_and_perfdata_items_whole() -> None:
    components = [
        component("/Laser/Laser2", 2, "No scans received", "laser2"),
        component("/Power/Robot Battery", 1, "Low", "it's one", voltage="11.2"),
        component("/Temp", 3, "old"),
        component("/Motor", 0, "OK"),
    ]
    verdict = judge_verdict(robot(*components), Settings(perfdata_values=True))
    assert verdict.state == CRITICAL
    assert (
        verdict.status_text
        == "CRITICAL - robot1: /Laser/Laser2 (No scans received) (also 1 WARNING, 1 UNKNOWN)"
    )
    assert [(title, [c.name for c in members]) for title, members in verdict.sections] == [
        ("CRITICAL sensor(s) list:", ["/Laser/Laser2"]),
        ("WARNING sensor(s) list:", ["/Power/Robot Battery"]),
        ("UNKNOWN (stale) sensor(s) list:", ["/Temp"]),
        ("OK sensor(s) list:", ["/Motor"]),
    ]
    # Items keep the spaces and doubled quotes of their labels: the push hands them to Icinga as they are.
    assert verdict.perfdata[-1] == "'/Power/Robot Battery[it''s one]:voltage'=11.2;;;;"
    assert plugin_output(verdict).splitlines()[0] == verdict.status_text + " | " + " ".join(verdict.perfdata)
    down = judge_verdict(robot(*components, up=False), Settings())
    assert (down.state, down.sections, down.perfdata) == (UNKNOWN, [], [])


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("12.70", 12.7),
        ("-3", -3.0),
        (".5", 0.5),
        ("1e3", 1000.0),
        (" 7 ", 7.0),
        ("nan", None),
        ("inf", None),
        ("1e999", None),
        ("1_000", None),
        ("0x10", None),
        ("", None),
        ("12 V", None),
    ],
)
def test_parse_number_accepts_plain_finite_numbers_only(text: str, expected: float | None) -> None:
    assert parse_number(text) == expected


@pytest.mark.parametrize(
    ("number", "expected"),
    [
        (12.7, "12.7"),
        (85.0, "85"),
        (-0.5, "-0.5"),
        (1.5e-07, "0.00000015"),
        (1e16, "10000000000000000"),
        (0.0, "0"),
    ],
)
def test_perf_number_never_uses_an_exponent(number: float, expected: str) -> None:
    assert perf_number(number) == expected


def test_perf_label_doubles_quotes_and_replaces_equals() -> None:
    assert perf_label("/Arm's joint=1:torque") == "'/Arm''s joint_1:torque'"


def document(**overrides: object) -> dict[str, object]:
    """A valid robot answer of the exporter, with `overrides`."""
    base: dict[str, object] = {
        "generated_at": 1700000001.5,
        "robot": "robot1",
        "level": 1,
        "state": "WARN",
        "up": True,
        "last_message": 1700000001.0,
        "transport": "dds",
        "counts": {"ok": 0, "warn": 1, "error": 0, "stale": 0},
        "components": [
            {
                "name": "/Power/Robot Battery",
                "hardware_id": "power1",
                "level": 1,
                "state": "WARN",
                "reported_level": 1,
                "stale": False,
                "message": "Low charge",
                "values": [{"key": "voltage", "value": "11.2"}],
                "last_update": 1700000001.0,
                "level_changes": 0,
            }
        ],
    }
    return {**base, **overrides}


def test_robot_from_document_reads_the_contracts_fields() -> None:
    parsed = robot_from_document(document())
    assert (parsed.name, parsed.up, parsed.last_message, parsed.generated_at) == (
        "robot1",
        True,
        1700000001.0,
        1700000001.5,
    )
    [battery] = parsed.components
    assert (battery.name, battery.hardware_id, battery.level, battery.message, list(battery.values)) == (
        "/Power/Robot Battery",
        "power1",
        1,
        "Low charge",
        [("voltage", "11.2")],
    )


def test_robot_from_document_accepts_a_robot_never_heard_from() -> None:
    assert robot_from_document(document(last_message=None, up=False, components=[])).last_message is None


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"components": None}, "'components' is missing or not a JSON array"),
        ({"up": "yes"}, "'up' is missing or not a JSON boolean"),
        ({"generated_at": True}, "'generated_at' is missing or not a JSON number"),
        ({"last_message": "now"}, "'last_message' is missing or not a JSON number"),
        ({"robot": 7}, "'robot' is missing or not a JSON string"),
        ({"components": [7]}, "a component is not a JSON object"),
        ({"components": [{"level": 4}]}, "component level 4 is not 0, 1, 2 or 3"),
        ({"components": [{"level": True}]}, "component level True is not 0, 1, 2 or 3"),
        (
            {"components": [{"level": 0, "name": "/A", "hardware_id": "", "message": "", "values": [1]}]},
            "a key-value is not a JSON object",
        ),
    ],
)
def test_robot_from_document_names_what_is_wrong(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(CheckError, match=re.escape(message)):
        robot_from_document(document(**overrides))


def test_robot_from_document_rejects_a_list() -> None:
    with pytest.raises(CheckError, match="not a JSON object"):
        robot_from_document([])
