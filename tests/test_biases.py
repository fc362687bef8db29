"""Biases to model parameters (pecs.biases, `pecs bias`). Expected numbers are worked by hand from
the published constants: libcaer's coarse currents (11, 94, 756, 6054, 48437, 387500, 3.1e6,
24.8e6 pA) and DAVIS346 defaults, C1/C2 = 20, C_sf = 581 fF, U_T = kT/q at 300 K; for the
IMX636, an EVK4's measured ON thresholds (0.27, 0.18, 0.15, 0.08 at offsets 0, -10, -20, -30)
and refractory periods (52 us at 0, 87 at -10, 38 at +10, 9 at +235)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.biases import (
    IMX636_RANGES,
    coarse_fine_current_pa,
    config_from_biases,
    map_biases,
    write_bias_file,
)
from pecs.biases.imx636 import fitted_d
from pecs.config import SensorConfig


@pytest.mark.parametrize(
    ("coarse", "fine", "pa"),
    [
        (4, 39, 7407.88),  # DiffBn default: 48437 x 39 / 255, "7.4 nA"
        (5, 255, 387500.0),  # OnBn default
        (4, 1, 189.95),  # OffBn default
        (2, 58, 171.95),  # PrBp default
        (1, 16, 5.898),  # PrSFBp default
        (4, 25, 4748.7),  # RefrBp default
        (7, 255, 24.8e6),  # the largest
        (3, 0, 0.0),  # fine 0: the bias is off
    ],
)
def test_coarse_fine_current_is_libcaers(coarse: int, fine: int, pa: float) -> None:
    assert coarse_fine_current_pa(coarse, fine) == pytest.approx(pa, rel=1e-4)


def test_davis346_defaults_give_the_reference_thresholds() -> None:
    p = map_biases("davis346", {}).parameters
    # I_on / I_diff = 387500 / 7407.88 = 52.31; I_diff / I_off = 39 exactly (same coarse).
    assert p["theta_on"].value == pytest.approx(math.log(52.31) / 20, rel=1e-4)
    assert p["theta_on"].value == pytest.approx(0.198, abs=5e-4)
    assert p["theta_off"].value == pytest.approx(math.log(39) / 20, rel=1e-12)
    # Against the preset's 0.2 / 0.2 and the road calibration's 0.245 / 0.267: the calibration
    # lies inside the stated range, at its upper half.
    for name, calibrated in (("theta_on", 0.245), ("theta_off", 0.267)):
        assert p[name].low < 0.2 < p[name].high
        assert p[name].value < calibrated <= p[name].high


def test_davis346_bandwidth_from_the_follower_bias() -> None:
    # tau = 581 fF x 25.852 mV / 5.898 pA = 2.5466 ms; cutoff 1 / (2 pi tau) = 62.50 Hz.
    mapping = map_biases("davis346", {})
    assert mapping.parameters["cutoff_hz"].value == pytest.approx(62.50, rel=1e-3)
    # Graca's check of the constants: 10 pA gives 1.5 ms, i.e. 106 Hz; PrSFBp 1/27 is 9.95 pA.
    ten_pa = map_biases("davis346", {"PrSFBp": "1/27"}).parameters["cutoff_hz"].value
    assert 1 / (2 * math.pi * ten_pa) == pytest.approx(1.5e-3 * 10 / 9.953, rel=2e-3)
    assert "PrBp" in mapping.unmapped


def test_davis346_refractory_is_the_presets_at_the_defaults_and_goes_as_one_over_current() -> None:
    preset = SensorConfig.preset("davis346").refractory_us
    at = {
        s: map_biases("davis346", {"RefrBp": s}).parameters["refractory_us"].value
        for s in ("4/25", "4/50", "4/100", "5/25")
    }
    assert at["4/25"] == pytest.approx(preset, rel=1e-12) and preset == 500.0
    assert at["4/50"] == pytest.approx(250.0) and at["4/100"] == pytest.approx(125.0)
    assert at["5/25"] == pytest.approx(500.0 * 48437 / 387500)  # one coarse step: 8x the current


def test_davis346_each_bias_moves_its_parameter_the_right_way() -> None:
    def value(bias: str, setting: str, field: str) -> float:
        return map_biases("davis346", {bias: setting}).parameters[field].value

    fines = ("20", "39", "80", "160")
    assert _increasing([value("OnBn", f"5/{f}", "theta_on") for f in ("40", "100", "255")])
    assert _increasing([-value("DiffBn", f"4/{f}", "theta_on") for f in fines])
    assert _increasing([value("DiffBn", f"4/{f}", "theta_off") for f in fines])
    assert _increasing([-value("OffBn", f"3/{f}", "theta_off") for f in ("10", "100", "255")])
    assert _increasing([value("PrSFBp", f"1/{f}", "cutoff_hz") for f in fines])
    assert _increasing([-value("RefrBp", f"4/{f}", "refractory_us") for f in fines])


def test_imx636_defaults_give_the_imx636_preset() -> None:
    assert config_from_biases("imx636", {}).to_dict() == SensorConfig.preset("imx636").to_dict()
    p = map_biases("imx636", {}).parameters
    assert (p["theta_on"].value, p["theta_off"].value, p["refractory_us"].value) == (0.3, 0.3, 100)
    assert p["cutoff_hz"].value == pytest.approx(1 / (2 * math.pi * 300e-6))
    assert "bias_hpf" in map_biases("imx636", {"bias_hpf": 60}).unmapped


def test_imx636_hand_worked_values() -> None:
    # D_on: u = [(-10)(-1/3) + (-20)(-4/9) + (-30)(-19/27)] / 1400 = (100/3) / 1400 -> D = 42.
    assert fitted_d() == pytest.approx(42.0, rel=1e-9)
    p = map_biases("imx636", {"bias_diff_on": 21}).parameters
    assert p["theta_on"].value == pytest.approx(0.45)  # 0.3 x (1 + 21/42)
    p = map_biases("imx636", {"bias_diff_off": 12}).parameters
    assert p["theta_off"].value == pytest.approx(0.3 * (1 + 12 / 42))  # the same D for OFF
    p = map_biases("imx636", {"bias_diff": 7}).parameters  # the reference, between the two
    assert p["theta_on"].value == pytest.approx(0.25) and p["theta_off"].value > 0.3
    refr = map_biases("imx636", {"bias_refr": -10}).parameters["refractory_us"].value
    assert refr == pytest.approx(100 * 87 / 52)
    refr = map_biases("imx636", {"bias_refr": 235}).parameters["refractory_us"].value
    assert refr == pytest.approx(100 * 9 / 52)
    # bias_fo: the per-step ratio (87/38)^(1/20) = 1.04229; 10 steps: x1.5131 on 530.5 Hz.
    cutoff = map_biases("imx636", {"bias_fo": 10}).parameters["cutoff_hz"].value
    assert cutoff == pytest.approx(530.52 * 1.5131, rel=1e-3)


def test_imx636_thresholds_follow_the_measured_ones() -> None:
    # The measurement relative to its own default, against the mapping relative to the preset.
    for offset, measured in ((-10, 0.18), (-20, 0.15), (-30, 0.08)):
        biases = {"bias_diff_on": offset}
        mapped = map_biases("imx636", biases).parameters["theta_on"].value / 0.3
        assert mapped == pytest.approx(measured / 0.27, abs=0.1)


def test_imx636_each_bias_moves_its_parameter_the_right_way() -> None:
    def values(bias: str, field: str) -> list[float]:
        low, high = IMX636_RANGES[bias]
        offsets = range(max(low, -20), high + 1, 5)
        return [map_biases("imx636", {bias: x}).parameters[field].value for x in offsets]

    assert _increasing(values("bias_diff_on", "theta_on"))
    assert _increasing(values("bias_diff_off", "theta_off"))
    assert _increasing([-v for v in values("bias_diff", "theta_on")])
    assert _increasing(values("bias_diff", "theta_off"))
    assert _increasing(values("bias_fo", "cutoff_hz"))
    refractory = values("bias_refr", "refractory_us")
    assert all(a >= b for a, b in zip(refractory, refractory[1:]))
    assert refractory[0] > 3 * refractory[4] > 10 * refractory[-1]


def test_every_estimate_holds_its_value_inside_its_range() -> None:
    for sensor, biases in (("davis346", {"OnBn": "6/30"}), ("imx636", {"bias_diff_on": -30})):
        for e in map_biases(sensor, biases).parameters.values():
            assert e.low < e.value < e.high and e.relation and e.set_by


@pytest.mark.parametrize("bias", sorted(IMX636_RANGES))
def test_an_imx636_bias_out_of_its_range_is_refused(bias: str) -> None:
    low, high = IMX636_RANGES[bias]
    for value in (low - 1, high + 1):
        with pytest.raises(
            ValueError, match=rf"^{bias}: {value} is out of its range {low}\.\.{high}$"
        ):
            map_biases("imx636", {bias: value})
    # The ends of the range map (but bias_diff_on below -40: its threshold would be zero).
    map_biases("imx636", {bias: max(low, -40)})
    map_biases("imx636", {bias: high})


@pytest.mark.parametrize(
    ("biases", "message"),
    [
        ({"OnBn": "8/255"}, r"^OnBn: coarse 8 is out of range 0-7"),
        ({"OnBn": "5/256"}, r"^OnBn: fine 256 is out of range 0-255"),
        ({"RefrBp": "4/0"}, r"^RefrBp: fine 0 turns the bias off"),
        ({"OnBn": "5-255"}, r"^OnBn: '5-255' is not COARSE/FINE"),
        ({"PixInvBn": "5/129"}, r"^PixInvBn: not a DAVIS346 bias pecs maps"),
        ({"OnBn": "4/20"}, r"^OnBn 4/20 \(3\.8 nA\) must give more current than DiffBn 4/39"),
        ({"OffBn": "4/40"}, r"^OffBn 4/40 .* must give less current than DiffBn 4/39"),
        ({"RefrBp": "0/1"}, r"^RefrBp 0/1 give refractory_us = 5\.504e\+07, outside the model"),
    ],
)
def test_a_bad_davis_bias_is_refused_in_one_line(biases: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message) as error:
        map_biases("davis346", biases)
    assert "\n" not in str(error.value)


def test_an_imx636_threshold_at_zero_is_refused_with_the_span_that_maps() -> None:
    # 0.3 (1 + x / 42) >= 0.01 -> x >= -40.6: -40 maps, -41 does not.
    map_biases("imx636", {"bias_diff_on": -40})
    with pytest.raises(ValueError, match=r"bias_diff_on - bias_diff = -41 .* >= -40$"):
        map_biases("imx636", {"bias_diff_on": -41})


@pytest.mark.parametrize(
    ("sensor", "biases"),
    [("imx636", {"bias_diff_on": 20, "bias_refr": -5}), ("davis346", {"OnBn": "5/200"})],
)
def test_a_sensor_file_of_biases_round_trips(tmp_path: Path, sensor: str, biases: dict) -> None:
    path = write_bias_file(map_biases(sensor, biases), tmp_path / "sensor.toml")
    assert "[biases]" in path.read_text()
    assert SensorConfig.from_file(path) == config_from_biases(sensor, biases)
    assert SensorConfig.from_file(path) != SensorConfig.preset(sensor)


def test_a_files_own_fields_win_over_its_biases(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text('theta_on = 0.5\nseed = 3\n[biases]\nsensor = "imx636"\nbias_diff_off = 12\n')
    config = SensorConfig.from_file(path)
    assert config.preset_name == "imx636" and config.theta_on == 0.5 and config.seed == 3
    assert config.theta_off == pytest.approx(0.3 * (1 + 12 / 42))
    assert config.width == 1280  # the rest from the sensor's preset


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[biases]\nbias_diff_on = 3\n", r"s\.toml: \[biases\]: name the sensor"),
        ('preset_name = "davis346"\n[biases]\nsensor = "imx636"\n', r"preset_name is \"davis346\""),
        (
            '[biases]\nsensor = "imx636"\nbias_fo = 99\n',
            r"bias_fo: 99 is out of its range -35\.\.55",
        ),
        ('[biases]\nsensor = "davis346"\nOnBn = 5\n', r"OnBn: 5 is not COARSE/FINE"),
        ("[other]\nx = 1\n", r"unknown sensor field 'other'"),
    ],
)
def test_a_bad_biases_table_is_refused_naming_the_file(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        SensorConfig.from_file(path)


def test_cli_prints_the_mapping_and_writes_a_sensor_file(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    code, out, err = run_cli(capsys, "bias", "davis346", "--set", "OnBn=5/255")
    assert code == 0 and err == ""
    assert "theta_on" in out and "0.1979" in out and "0.1832" in out and "62.5" in out
    output = tmp_path / "sensor.toml"
    code, out, err = run_cli(capsys, "bias", "imx636", "--bias-diff-on", "21", "-o", str(output))
    assert code == 0 and "0.45 " in out
    assert SensorConfig.from_file(output).theta_on == pytest.approx(0.45)


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["imx636", "--set", "bias_diff_on=141"], "bias_diff_on: 141 is out of its range -85..140"),
        (["imx636", "--bias-refr", "-21"], "--bias-refr: -21: expected a whole number in -20..235"),
        (["davis346", "--set", "OnBn=9/1"], "OnBn: coarse 9 is out of range 0-7"),
        (["davis346", "--bias-fo", "3"], "--bias-fo is an imx636 bias"),
    ],
)
def test_cli_refuses_a_bias_out_of_range_in_one_line(
    capsys: pytest.CaptureFixture, argv: list[str], expected: str
) -> None:
    code, out, err = run_cli(capsys, "bias", *argv)
    last = err.strip().splitlines()[-1]
    assert code == 2 and out == "" and expected in last and last.startswith("pecs bias: error: ")
    assert "Traceback" not in err and not PYTHON_SYNTAX.search(last)


def _increasing(values: list[float]) -> bool:
    return all(a < b for a, b in zip(values, values[1:]))
