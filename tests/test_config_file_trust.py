"""A sensor file that names a preset takes every field it leaves out from that preset; one that
names none (or a name that is no pecs preset) must give every field; an empty one is refused.
The preset's numbers checked by hand are those of the DAVIS346 preset's provenance comments
(python/pecs/config.py): refractory 0.5 ms, mismatch 0.03, latency 20 us, bandwidth 300 Hz,
dark current 1e-4, leak 0.001 Hz, hot pixels 1e-4 at 5 Hz."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.config import SensorConfig

FIELDS = [f.name for f in dataclasses.fields(SensorConfig)]
# What TOML cannot write (no null): absent means None, so no file has to give them.
OPTIONAL = {"lin_log_knee", "preset_name", "cfa"}


def sensor_file(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_file_naming_only_davis346_is_the_davis346_preset(tmp_path: Path) -> None:
    config = SensorConfig.from_file(sensor_file(tmp_path / "s.toml", 'preset_name = "davis346"\n'))
    assert config.to_dict() == SensorConfig.preset("davis346").to_dict()  # field by field
    assert config.preset_name == "davis346"
    hand = {
        "refractory_us": 500.0,
        "theta_sigma": 0.03,
        "latency_us": 20.0,
        "cutoff_hz": 300.0,
        "dark_current": 1e-4,
        "leak_rate_hz": 0.001,
        "hot_pixel_fraction": 1e-4,
        "hot_pixel_rate_hz": 5.0,
    }
    assert {name: getattr(config, name) for name in hand} == hand
    assert config.shot_rate_hz > 0 and config.jitter_us > 0 and config.theta_noise > 0


@pytest.mark.parametrize("name", SensorConfig.PRESETS)
def test_every_preset_named_alone_is_that_preset(tmp_path: Path, name: str) -> None:
    config = SensorConfig.from_file(sensor_file(tmp_path / "s.toml", f'preset_name = "{name}"\n'))
    assert config.to_dict() == SensorConfig.preset(name).to_dict()


def test_a_field_overridden_over_a_preset_is_the_only_difference(tmp_path: Path) -> None:
    text = 'preset_name = "davis346"\nrefractory_us = 123.0\n'
    config = SensorConfig.from_file(sensor_file(tmp_path / "s.toml", text))
    preset = SensorConfig.preset("davis346").to_dict()
    differing = {name for name, value in config.to_dict().items() if preset[name] != value}
    assert differing == {"refractory_us"} and config.refractory_us == 123.0


def test_a_file_naming_no_preset_must_give_every_field(tmp_path: Path) -> None:
    full = SensorConfig(theta_on=0.3, leak_rate_hz=0.01, seed=7)
    full.to_file(tmp_path / "full.toml")  # every field but the None ones
    assert SensorConfig.from_file(tmp_path / "full.toml") == full
    lines = (tmp_path / "full.toml").read_text().splitlines(keepends=True)
    partial = "".join(line for line in lines if not line.startswith(("theta_off ", "seed ")))
    with pytest.raises(ValueError, match=r"partial\.toml: .*missing: theta_off, seed$") as error:
        SensorConfig.from_file(sensor_file(tmp_path / "partial.toml", partial))
    assert "preset_name" in str(error.value)  # the way out: name a preset
    assert "\n" not in str(error.value)


def test_a_name_that_is_no_preset_must_give_every_field(tmp_path: Path) -> None:
    text = 'preset_name = "my_camera"\ntheta_on = 0.3\n'
    with pytest.raises(ValueError, match=r"'my_camera' is not a pecs preset") as error:
        SensorConfig.from_file(sensor_file(tmp_path / "s.toml", text))
    missing = str(error.value).split("missing: ")[1].split(", ")
    assert missing == [name for name in FIELDS if name not in OPTIONAL | {"theta_on"}]


@pytest.mark.parametrize("text", ["", "# pecs sensor configuration\n\n"])
def test_an_empty_file_is_refused(tmp_path: Path, text: str) -> None:
    with pytest.raises(ValueError, match=r"empty\.toml: no sensor fields"):
        SensorConfig.from_file(sensor_file(tmp_path / "empty.toml", text))


def test_the_cli_refuses_an_empty_or_partial_file_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    for text in ("", "theta_on = 0.3\n"):
        sensor = sensor_file(tmp_path / "sensor.toml", text)
        args = ["simulate", "checkerboard", "--config", str(sensor), "-o", str(tmp_path / "o")]
        code, out, err = run_cli(capsys, *args)
        assert code == 2 and out == ""
        assert err.count("\n") == 1 and err.startswith("pecs simulate: error: ")
        assert "preset_name" in err and not PYTHON_SYNTAX.search(err)
