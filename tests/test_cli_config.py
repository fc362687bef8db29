"""`--config SENSOR.toml` in the commands that simulate a dataset or the demo, and a dataset
spec's `config` key: the file's sensor fields (SensorConfig.from_file) are what the sequences
simulate, read back from the run's manifest, with the spec's sensor tables over them."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest
from pecs.cli import build_parser
from pecs.cli import main as cli_main
from pecs.cli.demo import demo_simulation
from pecs.config import SensorConfig
from pecs.dataset import load_spec
from pecs.render import Simulation

SPEC = """
[dataset]
name = "configured"
seed = 3

[defaults]
duration_s = 0.005
rate_hz = 1000
spp = 1
{config}

[defaults.sensor]
width = 32
height = 24

[[sequences]]
scene = "checkerboard"
{sequence}
"""

# Values no preset has, so that finding them in the run means the file was read.
FILE_FIELDS = {"theta_on": 0.37, "theta_off": 0.41, "refractory_us": 321.0, "seed": 99}


def write_sensor(path: Path, **fields: float | str) -> Path:
    preset = str(fields.pop("preset", "davis346"))
    SensorConfig.preset(preset, **{**FILE_FIELDS, **fields}).to_file(path)
    return path


def write_spec(folder: Path, config: str = "", sequence: str = "") -> Path:
    spec = folder / "spec.toml"
    spec.write_text(SPEC.format(config=config, sequence=sequence))
    return spec


def test_dataset_run_config_is_what_the_sequences_simulate(tmp_path: Path) -> None:
    sensor = write_sensor(tmp_path / "sensor.toml")
    spec, out = write_spec(tmp_path), tmp_path / "out"
    args = ["dataset", "run", str(spec), "-o", str(out), "--workers", "1", "--quiet"]
    assert cli_main([*args, "--config", str(sensor)]) == 0
    (record,) = json.loads((out / "manifest.json").read_text())["sequences"]
    used = record["config"]
    for name in ("theta_on", "theta_off", "refractory_us"):
        assert used[name] == FILE_FIELDS[name], name
    # the spec's sensor table goes over the file (the file says 346 x 260)
    assert (used["width"], used["height"]) == (32, 24)
    # each sequence's seed is drawn, not the file's
    assert used["seed"] == record["task"]["seed"] != FILE_FIELDS["seed"]
    # the events are those of pecs.Simulation given the file's SensorConfig (its size and seed
    # set as the spec sets them)
    configured = SensorConfig.from_file(sensor).replace(
        width=32, height=24, seed=record["task"]["seed"]
    )
    simulation = Simulation(
        "checkerboard", duration_s=0.005, rate_hz=1000, spp=1, seed=used["seed"], sensor=configured
    )
    expected = sum(batch.num_rows for batch in simulation.event_batches())
    assert record["events"] == expected > 0


def test_a_specs_config_key_is_relative_to_the_spec_and_a_sequences_own_wins(
    tmp_path: Path,
) -> None:
    (tmp_path / "sensors").mkdir()
    write_sensor(tmp_path / "sensors" / "base.toml")
    write_sensor(tmp_path / "sensors" / "own.toml", theta_on=0.55)
    spec = write_spec(tmp_path, config='config = "sensors/base.toml"')
    (task,) = load_spec(spec).sequences
    assert task.sensor["theta_off"] == 0.41 and task.sensor["width"] == 32
    assert "seed" not in task.sensor and "config" not in task.settings
    spec = write_spec(
        tmp_path, config='config = "sensors/base.toml"', sequence='config = "sensors/own.toml"'
    )
    (task,) = load_spec(spec).sequences
    assert task.sensor["theta_on"] == 0.55
    # the file's preset is the sequence's preset (film pixel pitch), unless one is stated
    write_sensor(tmp_path / "sensors" / "imx.toml", preset="imx636")
    spec = write_spec(tmp_path, config='config = "sensors/imx.toml"')
    (task,) = load_spec(spec).sequences
    assert task.settings["preset"] == "imx636"
    spec = write_spec(tmp_path, config='config = "sensors/imx.toml"\npreset = "esim"')
    (task,) = load_spec(spec).sequences
    assert task.settings["preset"] == "esim" and task.sensor["theta_on"] == 0.37
    # the command line's file replaces the spec's
    cli_file = SensorConfig.preset("imx636", theta_on=0.66)
    (task,) = load_spec(spec, cli_file).sequences
    assert task.sensor["theta_on"] == 0.66 and task.sensor["theta_off"] == cli_file.theta_off


def test_a_bad_sensor_file_in_a_spec_names_the_key_and_the_path(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, config='config = "missing.toml"')
    with pytest.raises(ValueError, match=r"defaults\.config: cannot use sensor file .*missing"):
        load_spec(spec)
    (tmp_path / "bad.toml").write_text("theta_on = -1\n")
    spec = write_spec(tmp_path, sequence='config = "bad.toml"')
    with pytest.raises(ValueError, match=r"sequences\[0\]\.config: .*bad\.toml.*theta_on"):
        load_spec(spec)


def test_demo_config_is_the_demos_sensor(tmp_path: Path) -> None:
    sensor = write_sensor(tmp_path / "sensor.toml", width=346, height=260)
    args = build_parser().parse_args(["demo", "--config", str(sensor)])
    used = demo_simulation(args).sensor_config
    for name in ("theta_on", "theta_off", "refractory_us"):
        assert getattr(used, name) == FILE_FIELDS[name], name
    default = demo_simulation(build_parser().parse_args(["demo"])).sensor_config
    assert default.theta_on != FILE_FIELDS["theta_on"]


def test_simulate_seed_is_the_sensors_seed_over_the_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sensor = write_sensor(tmp_path / "sensor.toml", width=32, height=24)
    built = []

    def capture(simulation: object, output: str, show: bool) -> object:
        built.append(simulation)
        return SimpleNamespace(events=0, frames=0, simulated_s=0.0, wall_s=0.0, out_dir=output)

    monkeypatch.setattr("pecs.cli.simulate.run_with_progress", capture)
    args = ["simulate", "checkerboard", "--config", str(sensor), "-o", str(tmp_path / "o")]
    assert cli_main([*args, "--seed", "5"]) == 0
    assert cli_main(args) == 0
    with_seed, without = (s.sensor_config for s in built)
    assert with_seed.seed == 5 and with_seed.theta_on == FILE_FIELDS["theta_on"]
    assert without.seed == FILE_FIELDS["seed"]


def test_simulation_seed_is_the_sensors_seed_over_a_configs(tmp_path: Path) -> None:
    config = SensorConfig.from_file(write_sensor(tmp_path / "sensor.toml", width=32, height=24))
    kwargs = {"duration_s": 0.002, "rate_hz": 1000, "spp": 1, "sensor": config}
    assert Simulation("checkerboard", seed=5, **kwargs).sensor_config.seed == 5
    assert Simulation("checkerboard", **kwargs).sensor_config.seed == FILE_FIELDS["seed"]


def test_a_config_with_a_preset_name_of_its_own_keeps_the_scenes_preset(tmp_path: Path) -> None:
    # A hand-written file may record any name: the scene's preset then sets the pixel pitch.
    sensor = write_sensor(tmp_path / "sensor.toml", width=32, height=24)
    sensor.write_text(sensor.read_text().replace('"davis346"', '"my_camera"'))
    config = SensorConfig.from_file(sensor)
    assert config.preset_name == "my_camera" and config.known_preset is None
    simulation = Simulation("checkerboard", duration_s=0.002, rate_hz=1000, spp=1, sensor=config)
    assert simulation.spec.preset == Simulation("checkerboard").spec.preset
    assert simulation.sensor_config.theta_on == FILE_FIELDS["theta_on"]


def test_dataset_config_replaces_the_specs_file_and_preset(tmp_path: Path) -> None:
    # The spec names a file that does not exist and a DAVIS346: --config's imx636 file is used
    # in place of both, without reading the spec's file.
    spec = write_spec(tmp_path, config='config = "missing.toml"\npreset = "davis346"')
    sensor = write_sensor(tmp_path / "imx.toml", preset="imx636")
    (task,) = load_spec(spec, sensor_config=SensorConfig.from_file(sensor)).sequences
    assert task.settings["preset"] == "imx636"
    assert task.sensor["theta_on"] == FILE_FIELDS["theta_on"]
    with pytest.raises(ValueError, match=r"defaults\.config: cannot use sensor file .*missing"):
        load_spec(spec)
