"""The effect registry (core/effects.py) is the one source of every effect's names, units and bounds.

The virtual CNC's ``--effect`` truth, the diagnosis's fitted effects, the axis model the
virtual machine runs and the JSON of an identify run all speak the registry's words: the
same effect has the same name, each quantity one name and one unit, and a value out of
range is refused the same way whichever way it came in.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from agent import cli
from core.effect_limits import check_effect_parameters
from core.effects import DESCRIBED_ONLY, EFFECT_NAMES, EFFECTS, MODEL, SIMULATOR, parameter_units, shown_unit
from core.errors import InputError
from ident.axis_model import EFFECT_NAMES as AXIS_EFFECTS
from ident.axis_model import AxisModel
from ident.diagnosis.augmented import EFFECTS as KERNEL_EFFECTS
from ident.diagnosis.augmented import EP_INDEX, MODE_SLOTS
from ident.diagnosis.config import DEFAULT
from ident.diagnosis.effects import EFFECT_MODELS
from ident.diagnosis.spec import ModelSpec, make_chunk
from ident.model import DriveModel
from virtual_cnc import effects as sim
from virtual_cnc.presets import load_machine

cli._register()
FIX = Path(__file__).resolve().parents[1] / "fixtures" / "diagnosis"
TS = 0.001
THETA = np.array([372.76, 62009.83, 1527104.87, 0.0, 0.0, 11106.33, 441.0, -302.0])

#: one spec per variant the diagnosis fits: (effect, parameters in EP_INDEX names, mode value)
VARIANTS = [
    *(("backlash", {"gap_mm": 0.02, "motor_fraction": 0.6, "position_motor_share": 0.3}, m) for m in (0, 1, 2)),
    ("stribeck", {"static_to_coulomb_ratio": 2.0, "stribeck_velocity_mm_s": 1.5}, None),
    *(("resonance", {"freq_hz": 80.0, "damping": 0.03, "gain": 0.7, "motor_fraction": 0.6,
                     "position_motor_share": 0.2}, m) for m in (0, 1, 2, 3)),
    *(("time_delay", {"delay_s": 0.004}, m) for m in (0, 1)),
    *(("cyclic_error", {"period_mm": 4.0, "amplitude_sin": 3.0, "amplitude_cos": 4.0}, m) for m in (0, 1)),
    *(("saturation", {"limit": 1500.0, "position_motor_share": 0.4}, m) for m in (0, 1)),
]


#: the values the words of each effect tell with a unit
TOLD = {"backlash": ("gap_mm",), "stribeck": ("stribeck_velocity_mm_s",), "resonance": ("freq_hz",),
        "time_delay": ("delay_s",), "cyclic_error": ("period_mm", "amplitude"), "saturation": ("limit",)}


def _spec(effect: str, params: dict, mode: int | None) -> ModelSpec:
    s = ModelSpec(THETA.copy()).with_effect(effect, params, mode)
    if effect == "time_delay":
        s.ranges["delay_s"] = (0.003, 0.005)  # a delay the recording leaves open: its range is reported
    return s


def _chunk():
    t = np.arange(2000) * TS
    x_r = 5.0 * np.sin(2 * np.pi * 0.5 * t)
    starts = np.zeros(t.size, dtype=bool)
    starts[0] = True
    return make_chunk(x_r, x_r.copy(), TS, starts)


def _model_params(effect: str, params: dict, mode: int | None) -> dict:
    return EFFECT_MODELS[effect].parameters(_spec(effect, params, mode), TS)


# ------------------------------------------------------------------ one list of effects

def test_every_effect_the_simulator_the_diagnosis_and_the_axis_model_know_is_the_registrys():
    assert tuple(sim.EFFECTS) == EFFECT_NAMES  # the --effect names
    assert tuple(EFFECT_MODELS) == EFFECT_NAMES  # the diagnosis's fitted effects
    assert AXIS_EFFECTS == EFFECT_NAMES == KERNEL_EFFECTS  # the axis model and its simulator's flag vector
    assert set(EFFECTS) == set(EFFECT_NAMES) | set(DESCRIBED_ONLY) and DESCRIBED_ONLY == ("external_force",)
    for name in EFFECT_NAMES:
        assert sim.EFFECTS[name].name == EFFECT_MODELS[name].name == EFFECTS[name].name == name
        assert sim.EFFECTS[name].primary == EFFECTS[name].primary


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_the_simulators_parameters_are_the_registrys_virtual_cnc_parameters(name):
    assert [f.name for f in fields(sim.EFFECTS[name])] == list(EFFECTS[name].names(SIMULATOR))


def test_each_quantity_has_one_unit_wherever_its_name_appears():
    units: dict[str, set[str]] = {}
    for e in EFFECTS.values():
        for p in e.parameters:
            units.setdefault(p.name, set()).add(p.unit)
            assert p.form in ("number", "word", "flag", "interval", "windows")
            assert (p.unit == "") == p.text, f"{e.name}.{p.name}: a number needs a unit, a word none"
    assert {k: u for k, u in units.items() if len(u) > 1} == {}
    # the two saturation limits are different quantities with different names
    sat = EFFECTS["saturation"]
    assert (sat.parameter("limit_v").unit, sat.parameter("limit_v").places) == ("V", (SIMULATOR,))
    assert (sat.parameter("limit").unit, sat.parameter("limit").places) == ("mm/s^2", (MODEL,))


# ------------------------------------------------------------------ the diagnosis speaks the registry

@pytest.mark.parametrize("effect, params, mode", VARIANTS)
def test_the_diagnosis_reports_registry_names_units_and_variant_words(effect, params, mode):
    entry = EFFECTS[effect]
    p = _model_params(effect, params, mode)
    assert set(p) <= set(entry.names(MODEL))
    for key, value in p.items():
        q = entry.parameter(key)
        if q.form == "word":  # one of the registry's words (and of its variants, for a variant's key)
            assert value in q.choices, (key, value)
            assert value in (entry.choices(key, MODEL) or q.choices), (key, value)
    check_effect_parameters(effect, p, complete=True)  # within the registry's ranges, nothing missing
    # the words name the effect as the registry does and carry the registry's unit of each
    # value they tell (a dead time in ms, its servo scale)
    words = EFFECT_MODELS[effect].words(p)
    assert words.startswith(entry.words)
    units = parameter_units(effect, p)
    for key in TOLD[effect]:
        assert (" ms" if key == "delay_s" else f" {shown_unit(units[key])}") in words, key


@pytest.mark.parametrize("effect, params, mode", VARIANTS)
def test_the_reported_parameters_are_the_simulators_arrays_both_ways(effect, params, mode):
    spec = _spec(effect, params, mode)
    p = EFFECT_MODELS[effect].parameters(spec, TS)
    ep, modes = np.zeros_like(spec.ep), np.zeros_like(spec.modes)
    EFFECT_MODELS[effect].set_arrays(p, ep, modes)
    for name in EFFECT_MODELS[effect].free(spec):
        assert ep[EP_INDEX[name]] == pytest.approx(spec.ep[EP_INDEX[name]], rel=1e-12), name
    if effect in MODE_SLOTS:
        assert modes[MODE_SLOTS[effect]] == spec.modes[MODE_SLOTS[effect]]


def test_every_fitted_coordinate_is_a_registry_parameter_and_its_search_box_inside_its_range():
    chunk = _chunk()
    coordinates = {k for e in EFFECTS.values() for k in e.coordinates}
    assert set(EP_INDEX) <= {p.name for e in EFFECTS.values() for p in e.parameters} | coordinates
    for effect, params, mode in VARIANTS:
        spec = _spec(effect, params, mode)
        for name in EFFECT_MODELS[effect].free(spec):
            if name in EFFECTS[effect].coordinates:
                continue
            lo, hi = EFFECT_MODELS[effect].bounds(name, float(spec.ep[EP_INDEX[name]]), chunk, DEFAULT)
            low, _, high, _ = EFFECTS[effect].parameter(name).limits
            assert low is None or lo >= low, (effect, name, lo)
            assert high is None or hi <= high, (effect, name, hi)


# ------------------------------------------------------------------ the axis model and the simulator

@pytest.mark.parametrize("effect, params, mode", VARIANTS)
def test_the_axis_model_carries_what_the_diagnosis_reports(effect, params, mode):
    """Every key the diagnosis writes, words and intervals included (a saturation's limit_unit,
    a dead time's delay_range_s), is one the virtual machine's model loads back."""
    p = _model_params(effect, params, mode)
    m = AxisModel(DriveModel(*THETA), TS, effects={effect: p})
    back = AxisModel.from_dict(json.loads(json.dumps(m.to_dict())))
    assert back.effects[effect] == p


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_the_simulators_truth_is_told_in_the_identified_models_words(name):
    plant = load_machine("fadal-ppi").axes["X"].plant
    kj = plant.K_over_J
    truth = sim.model_equivalent(sim.EFFECTS[name](), kj, plant.B_over_J)
    assert set(truth) <= set(EFFECTS[name].names(MODEL))
    AxisModel(DriveModel(*THETA), TS, effects={name: truth})  # admissible as a model
    if name == "saturation":  # V → mm/s² through the axis's K/J
        assert truth["limit"] == pytest.approx(kj * sim.Saturation().limit_v)
        assert truth["limit_slope"] == plant.B_over_J  # the viscous share eq. 3.3's a1 holds


@pytest.mark.parametrize("name, key, bad", [
    ("backlash", "gap_mm", -0.01), ("backlash", "motor_fraction", 1.0), ("stribeck", "static_to_coulomb_ratio", 0.5),
    ("stribeck", "stribeck_velocity_mm_s", 0.0), ("resonance", "freq_hz", 0.0), ("resonance", "damping", -0.1),
    ("time_delay", "delay_s", 2.0), ("cyclic_error", "period_mm", 0.0), ("cyclic_error", "amplitude", -1.0),
])
def test_a_value_out_of_range_is_refused_alike_by_the_simulator_and_the_axis_model(name, key, bad):
    with pytest.raises(InputError) as by_sim:
        sim.parse_effect(f"{name}={key}:{bad}")
    params = dict(sim.model_equivalent(sim.EFFECTS[name](), 1000.0), **{key: bad})
    with pytest.raises(InputError) as by_model:
        AxisModel(DriveModel(*THETA), TS, effects={name: params})
    assert str(by_sim.value) == str(by_model.value)
    assert str(by_sim.value).startswith(f"{name} {key} must be")


def test_the_axis_model_refuses_a_virtual_cnc_quantity_by_its_name():
    """A model clips the control-equivalent acceleration (``limit``, mm/s²); the virtual CNC's
    amplifier limit in volts (``limit_v``) is another quantity, refused by name, not ignored."""
    model = AxisModel(DriveModel(*THETA), TS, effects={"saturation": {"limit": 1500.0}})
    with pytest.raises(InputError, match=r"effect saturation: unknown parameter 'limit_v'; known: limit, "):
        model.with_parameter("saturation.limit_v", 2.0)
    assert model.with_parameter("saturation.limit", 1800.0).effects["saturation"]["limit"] == 1800.0


@pytest.mark.parametrize("old, new", [
    ("time_delay=delay_s:0.003,at:capture", "time_delay=delay_s:0.003,where:capture"),
    ("saturation=limit:1.5", "saturation=limit_v:1.5"),
    ("cyclic_error=period_mm:4,phase_deg:45", f"cyclic_error=period_mm:4,phase_rad:{math.pi / 4!r}"),
])
def test_older_spellings_read_as_the_registry_names(old, new):
    assert sim.parse_effect(old) == sim.parse_effect(new)
    assert sim.format_effect(sim.parse_effect(old)) == sim.format_effect(sim.parse_effect(new))


# ------------------------------------------------------------------ the JSON of an identify run

@pytest.mark.slow
def test_the_json_of_an_identify_run_uses_the_registrys_names_and_units(tmp_path):
    out = tmp_path / "r.json"
    res = CliRunner().invoke(cli.app, ["identify", str(FIX / "saturation.csv"), "--validate",
                                       str(FIX / "saturation_validation.csv"), "--json", str(out)])
    assert res.exit_code == 0, res.stderr
    axis = json.loads(out.read_text())["axes"]["X"]
    diag = axis["diagnosis"]
    assert {c["effect"] for c in diag["candidates"]} >= set(EFFECT_NAMES)
    for c in diag["candidates"]:
        entry = EFFECTS[c["effect"]]
        assert set(c["parameters"]) <= set(entry.names(MODEL)), c["effect"]
        assert c["parameter_units"] == parameter_units(c["effect"], c["parameters"])
        assert set(c["parameters_interval95"]) <= set(entry.names(MODEL))
    named = next(c for c in diag["candidates"] if c["effect"] == "saturation" and c["accepted"])
    assert named["parameters"]["limit_unit"] == named["parameter_units"]["limit"] == "mm/s^2"
    # the truth, an amplifier limit in V, told as the model's acceleration limit
    truth = sim.model_equivalent(sim.parse_effect(json.loads((FIX / "cases.json").read_text())["saturation"]
                                                  ["effect_text"]), load_machine("fadal-ppi").axes["X"].plant.K_over_J)
    assert named["parameters"]["limit"] == pytest.approx(truth["limit"], rel=0.25)
    # the virtual machine runs what the JSON holds
    effects = diag["augmented_model"]["effects"]
    assert AxisModel.from_dict(axis["virtual_model"]).effects == effects
