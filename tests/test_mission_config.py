"""One typed mission: every shipped file parses, flags override fields, errors name the key or the flag."""

from __future__ import annotations

import pytest

from layerpilot.config import ConfigError
from layerpilot.missionfile import MISSION_DIR, Mission, Override, load_mission


@pytest.mark.parametrize("path", sorted(MISSION_DIR.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_mission_parses_into_typed_sections(path) -> None:
    m = load_mission(path)
    assert isinstance(m, Mission) and m.vehicles
    assert m.map_server.resolution > 0 and m.sim.camera.width >= 16 and m.evaluation.duration > 0


def test_flags_override_fields_of_the_parsed_mission() -> None:
    m = load_mission("default", [Override("--world-size", "sim.world.size", 600.0),
                                 Override("--behavior", "decide.behavior", "orbit"),
                                 Override("--duration", "evaluation.duration", 30.0)])
    assert m.sim.world.size == 600.0 and m.decide.behavior == "orbit" and m.evaluation.duration == 30.0
    assert m.sim.camera.width == load_mission("default").sim.camera.width  # the rest is the file's


@pytest.mark.parametrize("override, message", [
    (Override("--world-size", "sim.world.size", -1.0), r"^--world-size must be in \[20.0, 5000.0\], got -1.0$"),
    (Override("--duration", "evaluation.duration", 0.0), r"^--duration must be in \[1.0, 36000.0\], got 0.0$"),
    (Override("--behavior", "decide.behavior", "nonsense"),
     r"^--behavior 'nonsense': not a file and not a preset \(balanced, .*, orbit-rings, survey, .*\)$"),
])
def test_a_bad_flag_value_is_reported_under_the_flags_name(override, message) -> None:
    with pytest.raises(ConfigError, match=message):
        load_mission("default", [override])


def test_a_bad_key_in_a_file_is_reported_with_its_path(tmp_path) -> None:
    path = tmp_path / "m.toml"
    path.write_text("[map_server]\nresolution = 1.0\nresolutoin = 2.0\n")
    with pytest.raises(ConfigError, match=r"m.toml: .*map_server.resolutoin"):
        load_mission(path)
    path.write_text("[sim.world]\nsize = 1.0\n")
    with pytest.raises(ConfigError, match=r"size = 1.0 is out of range"):
        load_mission(path)
    path.write_text("[evaluation]\nduration = 'long'\n")
    with pytest.raises(ConfigError, match=r"evaluation.duration: expected a number"):
        load_mission(path)


def _keys(cls, prefix: str = "") -> list[str]:
    import dataclasses
    import typing

    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        out += _keys(tp, f"{prefix}{f.name}.") if dataclasses.is_dataclass(tp) else [prefix + f.name]
    return out


def test_every_mission_key_is_in_the_documented_table() -> None:
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "missions.md").read_text()
    missing = [k for k in _keys(Mission) if f"| `{k}` |" not in doc]
    assert not missing, f"docs/missions.md lacks {missing}"


def test_demo_and_study_choose_the_sensor_profile_by_flag() -> None:
    from layerpilot.cli import build_parser
    from layerpilot.cli.eval import _mission

    for command in ("demo", "study"):
        args = build_parser().parse_args([command, "--config", "consumer", "--sensors", "rtk"])
        mission = _mission(args)
        assert mission.sim.sensors == "rtk" and mission.sim.sensor_overrides == load_mission("consumer").sim.sensor_overrides
    args = build_parser().parse_args(["demo", "--sensors", "lidar"])
    with pytest.raises(ConfigError, match=r"^--sensors 'lidar': expected one of 'perfect', 'rtk', 'consumer', 'degraded'"):
        _mission(args)
