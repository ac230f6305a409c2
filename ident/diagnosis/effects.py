"""The effects of SPEC §7, one object each: parameters, bounds, starts, meaning, words.

An :class:`Effect` knows everything the diagnosis needs of one piece of physics the base
model of eq. 3.3 leaves out, so the algorithm in :mod:`ident.diagnosis.diagnose` and the
search in :mod:`ident.diagnosis.candidates` never ask which effect they hold:

- ``free(spec)``: the parameters the output-error fit moves (names of ``EP_INDEX``),
  ``bounds``/``scale_floor`` for each; ``added``: how many the acceptance rule
  charges for;
- ``starts(base, chunk, evidence)``: starting models, led by the residual's localisation
  (spectrum peaks, position periodogram, |u| percentiles) and covering each structural
  variant (where the loop reads position, where a delay sits, whether an integrator is
  protected from windup …);
- ``parameters(spec)`` / ``set_arrays(p, ep, modes)``: SPEC §7 words ↔ simulator arrays
  (:mod:`ident.diagnosis.augmented`), also used by :class:`ident.axis_model.AxisModel`;
- ``implausible(spec, chunk)``: why fitted values are not the physics the name means ("" if
  they are) — part of the effect's definition (a gap the scales resolve, a mode below the
  Nyquist band, a dead time beyond the lag of sampling), never a signature veto and never a
  parameter on a bound of its fit's box: that parameter is *not resolved*
  (:mod:`ident.diagnosis.intervals`), which the words say, and the effect is judged by its
  held-out likelihood ratio all the same;
- ``words(p, intervals, unresolved)`` and ``signature(loc)``: what the user reads (each
  value with its 95 % interval or "not resolved"), what the localisation shows.

Names, parameter names, units, the words of each variant (``loop``, ``kind``, ``where`` …)
and admissible ranges are the effect registry's (:mod:`core.effects`); what lives here is
how the diagnosis fits them (search boxes inside those ranges, starts, steps).
"""

from __future__ import annotations

import math

import numpy as np

from core.effects import EFFECTS as REGISTRY
from core.effects import MODEL, shown_unit
from ident.diagnosis.augmented import EP_INDEX, MODE_SLOTS
from ident.diagnosis.config import DiagnosisConfig
from ident.diagnosis.spec import Chunk, ModelSpec, simulate_spec, sse
from ident.portable_math import geomspace

__all__ = ["Effect", "TimeDelay", "EFFECT_MODELS", "effect_parameters", "cascade_motor_share", "motor_shares",
           "told"]


def cascade_motor_share(theta: np.ndarray) -> float:
    """ψ, the share of the position feedback that reads the motor, of a P-PI cascade with θ of eq. 3.3.

    A P-PI cascade (position gain Kp, velocity loop Kv + Ki/s on the motor, velocity
    feed-forward kvff) gives ``u = Kv·Kp·(x_r − x_table) + Ki·Kp·∫(x_r − x_table) − Kv·ẋ
    − Ki·x_motor + (Kv·kvff·ẋ_r + Ki·kvff·x_r)``, per unit mass: a1 = Kv, a2 = Kv·Kp + Ki,
    a3 = Ki·Kp, so Kp is a root of ``a1·Kp² − a2·Kp + a3 = 0`` — the smaller one: the
    position gain lies below the velocity loop's PI corner Ki/Kv, the other root — and
    ψ = Ki/a2 = 1 − a1·Kp/a2 (Table 3.3: 0.819).  The feed-forward does not enter.
    """
    a1, a2, a3 = float(theta[0]), float(theta[1]), float(theta[2])
    if not (a1 > 0.0 and a2 > 0.0 and a3 > 0.0):
        return 0.0
    kp = (a2 - math.sqrt(max(a2 * a2 - 4.0 * a1 * a3, 0.0))) / (2.0 * a1)
    return float(np.clip(1.0 - a1 * kp / a2, 0.0, 1.0))


def motor_shares(theta: np.ndarray) -> tuple[float, ...]:
    """The readings of ψ (see :func:`cascade_motor_share`) the base's θ allows, to start fits from.

    The rigid model cannot tell a P-PI cascade from a PID: 1 − b2/a2 is ψ of a cascade
    without velocity feed-forward (Ki·kvff·x_r adds to b2) and 0 for a PID on the scale
    (b2 = a2), whose θ reads as a cascade all the same.  Both readings, the second left
    out when within 0.05 of the first.
    """
    a2, b2 = float(theta[1]), float(theta[5])
    plain = float(np.clip(1.0 - b2 / a2, 0.0, 1.0)) if a2 > 0.0 else 0.0
    cascade = cascade_motor_share(theta)
    return (plain,) if abs(cascade - plain) < 0.05 else (plain, cascade)


def _vmax(chunk: Chunk) -> float:
    return float(np.max(np.abs(chunk.derivs[0]))) or 1.0


def _amax(chunk: Chunk) -> float:
    return float(np.max(np.abs(chunk.derivs[1]))) or 1.0


class Effect:
    """One effect of SPEC §7 (subclasses below; instances in :data:`EFFECT_MODELS`)."""

    name: str = ""
    #: parameters the acceptance rule charges for
    added: int = 1
    #: scale floors of the fit's scaled coordinates z = p / max(|p0|, floor)
    scale_floor: dict[str, float] = {}
    #: two-mass variants (a stiff contact or a mode inside the loop) simulate on up to
    #: 16 sub-steps a sample: their searches take 3-5x the others' and are started first,
    #: so the diagnosis's two worker threads end together
    two_mass: bool = False
    #: the model's whole state can be read from the recording at a restart mid-move
    #: (:meth:`~ident.diagnosis.spec.Chunk.windows`): its search may race on such windows;
    #: one that is not races on windows restarted at rests
    #: (:meth:`~ident.diagnosis.spec.Chunk.rest_windows`), or on whole segments where the
    #: recording shows no rest (then among the longest: started with the two-mass ones)
    restartable: bool = True

    def free(self, spec: ModelSpec) -> list[str]:
        raise NotImplementedError

    def bounds(self, name: str, p0: float, chunk: Chunk, cfg: DiagnosisConfig) -> tuple[float, float]:
        if name == "motor_fraction":
            return 0.2, 0.98
        raise KeyError(name)

    def starts(self, base: ModelSpec, chunk: Chunk, evidence: dict, cfg: DiagnosisConfig) -> list[ModelSpec]:
        raise NotImplementedError

    def finish(self, spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
        """The fitted model as reported (an effect whose parameter the data leave open says so)."""
        return spec

    def parameters(self, spec: ModelSpec, Ts: float | None = None) -> dict:
        """The fitted parameters in the words of SPEC §7; ``Ts`` (the sample period) lets an
        effect tell them without what the sampling adds (a dead time beyond the lag of a digital loop)."""
        raise NotImplementedError

    def set_arrays(self, p: dict, ep: np.ndarray, modes: np.ndarray) -> None:
        raise NotImplementedError

    def implausible(self, spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> str:
        """Why the fitted ``spec`` is not the physics the name means on ``chunk`` ("" if it is)."""
        return ""

    def words(self, p: dict, intervals: dict | None = None, unresolved: dict | None = None) -> str:
        """The effect in the user's words, each value with its 95 % interval (``intervals``:
        name → [lo, hi]) or why it is not resolved (``unresolved``: name → why)."""
        return self.name

    def signature(self, loc: dict) -> dict:
        return {}

    def variant(self, spec: ModelSpec) -> int:
        return int(spec.modes[MODE_SLOTS[self.name]]) if self.name in MODE_SLOTS else 0

    @property
    def called(self) -> str:
        """How a sentence names the effect (the registry's words: "time delay")."""
        return REGISTRY[self.name].words

    def said(self, p: dict, key: str, fmt: str, intervals: dict | None = None, unresolved: dict | None = None) -> str:
        """:func:`told` with the registry's unit of ``key``."""
        return told(p, key, fmt, _unit(self.name, key), intervals, unresolved)


def _read(spec: ModelSpec, *names: str) -> dict[str, float]:
    """The named effect parameters of ``spec`` (slots of ``EP_INDEX``) as floats."""
    return {k: float(spec.ep[EP_INDEX[k]]) for k in names}


def _variants(effect: str, key: str) -> tuple:
    """The words of ``effect``'s variant parameter ``key`` by the simulator's mode value (registry order)."""
    return REGISTRY[effect].choices(key, MODEL)


def _unit(effect: str, key: str) -> str:
    """" mm", " mm/s²" …: the registry's unit of ``key`` as a sentence shows it after a value."""
    u = shown_unit(REGISTRY[effect].parameter(key).unit)
    return f" {u}" if u and u != "-" else ""


def told(p: dict, key: str, fmt: str, unit: str = "", intervals: dict | None = None,
         unresolved: dict | None = None, scale: float = 1.0) -> str:
    """``p[key]`` in words with what the data say of it: "0.03 (0.01–0.08)", "0.15 (not
    resolved: held at the fit's bound 0.15)" or the bare value when no interval is known.
    ``scale`` multiplies value and interval (s → ms)."""
    v = f"{scale * p[key]:{fmt}}{unit}"
    if unresolved and key in unresolved:
        return f"{v} (not resolved: {unresolved[key]})"
    if intervals and key in intervals:
        lo, hi = intervals[key]
        return f"{v} ({scale * lo:{fmt}}–{scale * hi:{fmt}}{unit})"
    return v


def _concentration(loc: dict, share: str, time_share: str) -> float:
    t = loc.get(time_share, 0.0)
    return float(loc.get(share, 0.0) / t) if t > 0 else 0.0


class Backlash(Effect):
    """A dead band between motor and table (mode 0: loop on the motor, a massless table
    recorded; mode 1: two masses across a stiff contact, the loop reading the table; mode 2:
    the two masses with the loop on the motor and the table recorded)."""

    name = REGISTRY["backlash"].name
    added = 2
    two_mass = True
    scale_floor = {"gap_mm": 1e-3, "position_motor_share": 0.1}
    #: starting gaps, mm: a log grid over what feed drives show (1 µm … 1 mm)
    start_gaps_mm = (0.003, 0.01, 0.03, 0.1, 0.3)

    def free(self, spec):
        # the full-closed loop's position term reads the motor in part (ψ): started at the
        # readings of θ (motor_shares), fitted beside the gap, which trades with it
        v = self.variant(spec)
        two_mass = ["gap_mm", "motor_fraction"] if v >= 1 else ["gap_mm"]
        return two_mass + ["position_motor_share"] if v == 1 else two_mass

    def bounds(self, name, p0, chunk, cfg):
        return (0.0, 1.0) if name in ("gap_mm", "position_motor_share") else super().bounds(name, p0, chunk, cfg)

    def starts(self, base, chunk, evidence, cfg):
        shares = motor_shares(base.theta)
        out = []
        for g in self.start_gaps_mm:
            out.append(base.with_effect(self.name, {"gap_mm": g}, 0))
            # two masses: the loop on the table, its position term reading the motor in part
            # (share ψ); or semi-closed with the table's inertia, every loop term on the motor
            for mode, share, offset_share in [(1, p, p) for p in shares] + [(2, 0.0, 0.0)]:
                s = base.with_effect(self.name, {"gap_mm": g, "motor_fraction": 0.8 if mode == 1 else 0.5,
                                                 "position_motor_share": share}, mode)
                if mode == 2:
                    # how far the table coasts into the gap when the motor brakes is set by
                    # the table's friction, which the base fitted without the gap made
                    # lopsided: start it equal both ways at its mean (and the motor's share of
                    # the inertia, unknown, at the middle of its range)
                    d_mean = 0.5 * (abs(s.theta[6]) + abs(s.theta[7]))
                    s.theta[6], s.theta[7] = d_mean, -d_mean
                # with the motor leading the table by half the gap in steady motion, a loop
                # on the table whose position term reads the motor (share ψ) sees an offset
                # a2·ψ·g/2 against the motion, which the base fitted without the gap took as
                # Coulomb friction: given back.  Not in mode 2: a loop on the motor alone
                # never sees the gap, only the recording does (with a2·g/2 given back a
                # 0.6 mm gap started 8x dearer than without and was screened out, s1042.0)
                offset = s.theta[1] * offset_share * 0.5 * g
                s.theta[6] -= offset
                s.theta[7] += offset
                out.append(s)
        return out

    def parameters(self, spec, Ts=None):
        loop = _variants(self.name, "loop")[int(spec.modes[MODE_SLOTS["backlash"]])]
        out = {**_read(spec, "gap_mm"), "loop": loop}
        if spec.modes[MODE_SLOTS["backlash"]]:
            out.update(_read(spec, "motor_fraction", "position_motor_share"))
        return out

    def set_arrays(self, p, ep, modes):
        ep[EP_INDEX["gap_mm"]] = p["gap_mm"]
        loops = _variants(self.name, "loop")
        if p.get("loop") in loops[1:]:
            modes[MODE_SLOTS["backlash"]] = loops.index(p["loop"])
            ep[EP_INDEX["motor_fraction"]] = p.get("motor_fraction", 0.5)
            ep[EP_INDEX["position_motor_share"]] = p.get("position_motor_share", 0.0)

    def implausible(self, spec, chunk, cfg):
        g = float(spec.ep[EP_INDEX["gap_mm"]])
        return f"gap below {1e3 * cfg.min_gap_mm:.0f} µm" if g < cfg.min_gap_mm else ""

    def words(self, p, intervals=None, unresolved=None):
        return f"{self.called}, gap {self.said(p, 'gap_mm', '.3g', intervals, unresolved)}"

    def signature(self, loc):
        return {"after_reversal_30ms_share": loc.get("after_reversal_30ms_share", 0.0),
                "concentration": _concentration(loc, "after_reversal_30ms_share", "after_reversal_30ms_time_share")}


class Stribeck(Effect):
    """Breakaway friction r·d at rest falling to Coulomb d with speed (v_s)."""

    name = REGISTRY["stribeck"].name
    added = 2
    scale_floor = {"stribeck_velocity_mm_s": 0.1}

    def free(self, spec):
        return ["static_to_coulomb_ratio", "stribeck_velocity_mm_s"]

    def bounds(self, name, p0, chunk, cfg):
        return (1.0, 20.0) if name == "static_to_coulomb_ratio" else (1e-4, _vmax(chunk))

    def starts(self, base, chunk, evidence, cfg):
        return [base.with_effect(self.name, {"static_to_coulomb_ratio": r, "stribeck_velocity_mm_s": v})
                for r in (1.5, 3.0, 5.0) for v in (0.2, 1.0, 0.02 * _vmax(chunk))]

    def parameters(self, spec, Ts=None):
        return _read(spec, "static_to_coulomb_ratio", "stribeck_velocity_mm_s")

    def set_arrays(self, p, ep, modes):
        for k in ("static_to_coulomb_ratio", "stribeck_velocity_mm_s"):
            ep[EP_INDEX[k]] = p[k]

    def implausible(self, spec, chunk, cfg):
        r = float(spec.ep[EP_INDEX["static_to_coulomb_ratio"]])
        return (f"breakaway within {100 * (cfg.min_static_ratio - 1):.0f} % of Coulomb friction"
                if r < cfg.min_static_ratio else "")

    def words(self, p, intervals=None, unresolved=None):
        ratio = self.said(p, 'static_to_coulomb_ratio', '.2g', intervals, unresolved)
        return (f"{self.called}, static/Coulomb {ratio}, "
                f"Stribeck velocity {self.said(p, 'stribeck_velocity_mm_s', '.2g', intervals, unresolved)}")

    def signature(self, loc):
        return {"low_speed_share": loc.get("low_speed_share", 0.0) + loc.get("at_rest_share", 0.0),
                "concentration": _concentration(loc, "low_speed_share", "low_speed_time_share")}


class Resonance(Effect):
    """A lightly damped pole pair: a filter on the recorded position (mode 0) or the
    free-free mode of a two-mass drive inside the loop, closed on the table (mode 1) or on
    the motor with the table recorded (mode 2) or with the motor recorded (mode 3: a
    controller's scope of a motor-encoder loop, where the mode shows only through the
    table's reaction on the motor)."""

    name = REGISTRY["resonance"].name
    added = 3
    two_mass = True
    scale_floor = {"gain": 0.1}

    def free(self, spec):
        extra = "motor_fraction" if self.variant(spec) >= 1 else "gain"
        return ["freq_hz", "damping", extra]

    def bounds(self, name, p0, chunk, cfg):
        if name == "freq_hz":
            return 0.5, 0.45 / chunk.Ts
        if name == "damping":  # the definition of a resonance bounds the fit (config.max_mode_damping)
            return 0.002, cfg.max_mode_damping
        if name == "gain":
            return -5.0, 5.0
        return super().bounds(name, p0, chunk, cfg)

    def starts(self, base, chunk, evidence, cfg):
        Ts = chunk.Ts
        peaks = [p["freq_hz"] for p in evidence.get("spectrum_peaks", [])[:2]
                 if p["freq_hz"] > cfg.min_mode_hz
                 and max(p.get("share_above_20_hz", 0.0), p.get("power_share", 0.0)) >= cfg.peak_min_share]
        # then a log grid over the band machine-tool modes occupy (10 Hz up to 0.3/Ts)
        fs = list(peaks)
        for f in geomspace(10.0, 0.3 / Ts, cfg.mode_grid_points):
            if all(abs(math.log(f / c)) > 0.2 for c in fs):
                fs.append(float(f))
        shares = dict.fromkeys((0.0,) + motor_shares(base.theta))
        out = []
        for f in fs:
            # a mode started at a residual spectrum peak stays near it (a two-mass mode shows
            # in closed loop a little below its free-free frequency: cfg.peak_band × the peak)
            box = {"freq_hz": (cfg.peak_band[0] * f, cfg.peak_band[1] * f)} if f in peaks else {}
            zeta = 0.02 if f in peaks else 0.05
            variants = [({"gain": 1.0}, 0)] + [({"motor_fraction": 0.8, "position_motor_share": p}, 1)
                                               for p in shares]
            variants.append(({"motor_fraction": 0.5, "position_motor_share": 0.0}, 2))
            if cfg.motor_recorded_mode:
                variants.append(({"motor_fraction": 0.5, "position_motor_share": 0.0}, 3))
            for extra, mode in variants:
                s = base.with_effect(self.name, {"freq_hz": f, "damping": zeta, **extra}, mode)
                s.box.update(box)
                out.append(s)
        return out

    def parameters(self, spec, Ts=None):
        if spec.modes[MODE_SLOTS["resonance"]]:
            # the free-free mode f and the motor's share μ trade along f·√μ, the frequency the
            # table rings at when a stiff velocity loop holds the motor: what a recording
            # fixes best (candidates.scan_motor_fraction), told beside f
            kinds, loops = _variants(self.name, "kind"), _variants(self.name, "loop")
            out = _read(spec, "freq_hz", "damping", "motor_fraction")
            return {**out, "kind": kinds[1], "loop": loops[int(spec.modes[MODE_SLOTS["resonance"]]) - 1],
                    **_read(spec, "position_motor_share"),
                    "locked_motor_hz": out["freq_hz"] * math.sqrt(max(out["motor_fraction"], 0.0))}
        return {**_read(spec, "freq_hz", "damping", "gain"), "kind": _variants(self.name, "kind")[0]}

    def set_arrays(self, p, ep, modes):
        ep[EP_INDEX["freq_hz"]], ep[EP_INDEX["damping"]] = p["freq_hz"], p["damping"]
        if p.get("kind") == _variants(self.name, "kind")[1]:
            loops = _variants(self.name, "loop")
            modes[MODE_SLOTS["resonance"]] = 1 + loops.index(p.get("loop", loops[0]))
            ep[EP_INDEX["motor_fraction"]] = p.get("motor_fraction", 0.5)
            ep[EP_INDEX["position_motor_share"]] = p.get("position_motor_share", ep[EP_INDEX["position_motor_share"]])
        else:
            ep[EP_INDEX["gain"]] = p.get("gain", 1.0)

    def implausible(self, spec, chunk, cfg):
        # The definition of the effect (SPEC §7: a *lightly damped* structural mode, below the
        # Nyquist band).  A damping held at the upper bound (config.max_mode_damping) means
        # the data want a better-damped pole pair than a lightly damped mode: a filter, which
        # eq. 3.3's continuous loop lacks against a digital controller — on a clean LinuxCNC
        # axis such a 253 Hz "mode" at ζ 0.15 passed the likelihood test (26 % of the held-out
        # residual).  A damping at the lower bound is a mode whose damping is not resolved.
        f, z = float(spec.ep[EP_INDEX["freq_hz"]]), float(spec.ep[EP_INDEX["damping"]])
        if f > 0.45 / chunk.Ts:
            return f"mode at {f:.0f} Hz, beyond 0.45/Ts"
        if z >= (1.0 - 1e-3) * cfg.max_mode_damping:
            return f"not a lightly damped mode (ζ = {z:.2f} on the bound of a lightly damped one, {f:.0f} Hz)"
        return ""

    def finish(self, spec, chunk, cfg):
        from ident.diagnosis.candidates import scan_motor_fraction

        return scan_motor_fraction(spec, chunk, cfg)

    def words(self, p, intervals=None, unresolved=None):
        damping = ("damping not resolved (" + unresolved["damping"] + ")" if unresolved and "damping" in unresolved
                   else f"damping {told(p, 'damping', '.3f', '', intervals, unresolved)}")
        # a mode whose damping the data leave open is still an oscillation at that frequency
        what = "an oscillatory mode" if unresolved and "damping" in unresolved else self.called
        hz = _unit(self.name, "freq_hz")
        if p.get("loop") == _variants(self.name, "loop")[2]:
            what += " between motor and table, seen on the motor encoder,"
        if "locked_motor_hz" in p:
            return (f"{what} at {told(p, 'freq_hz', '.1f', hz, intervals, unresolved)} (free two-mass mode; the "
                    f"table rings at {told(p, 'locked_motor_hz', '.1f', hz, intervals, unresolved)} with the "
                    f"motor held), {damping}")
        return f"{what} at {told(p, 'freq_hz', '.1f', hz, intervals, unresolved)}, {damping}"

    def signature(self, loc):
        peaks = loc.get("spectrum_peaks", [])
        top = peaks[0] if peaks else {"freq_hz": 0.0, "power_share": 0.0, "prominence": 0.0}
        return {"peak_freq_hz": top["freq_hz"], "peak_power_share": top["power_share"],
                "prominence": top["prominence"]}


class TimeDelay(Effect):
    """A dead time on the recorded position (mode 0) or inside the loop (mode 1)."""

    name = REGISTRY["time_delay"].name
    added = 1
    scale_floor = {"delay_s": 1e-3}
    #: dead times (samples) the regression starts know: a log grid up to the 10 ms a
    #: networked drive's capture or a slow servo cycle may add
    regression_samples = (1, 2, 3, 5, 8, 12)

    def free(self, spec):
        return ["delay_s"]

    def bounds(self, name, p0, chunk, cfg):
        return 0.0, 0.1

    def starts(self, base, chunk, evidence, cfg):
        from ident.diagnosis.candidates import chunk_regression, delayed_regression_start

        Ts = chunk.Ts
        out = [base.with_effect(self.name, {"delay_s": d * Ts}, mode) for d in (0.7, 1.5, 3.0, 6.0) for mode in (0, 1)]
        # the valley of a dead time can lie far from the base identified without it (gains
        # 2-3x lower inside the loop; a capture delay the base took as a slower loop): start
        # there too, from the regression of eq. 3.11 that knows the delay — m samples on the
        # control-equivalent acceleration (inside the loop; on the sampled controller
        # ≈ m − 1 samples of dead time, the hold and the sampled velocity add about one) or
        # on the captured position (the command paired m samples earlier)
        lag = 1 if base.sampled else 0
        reg = chunk_regression(chunk)
        for m in self.regression_samples:
            for mode, s0 in ((1, delayed_regression_start(chunk, m, reg) if reg is not None else None),
                             (0, self._capture_start(chunk, m))):
                if s0 is not None:
                    s0.modes[:] = base.modes
                    s0.origin = "delayed regression"
                    out.append(s0.with_effect(self.name, {"delay_s": max(m - lag * mode, 0.5) * Ts}, mode))
        return out

    @staticmethod
    def _capture_start(chunk: Chunk, m: int) -> ModelSpec | None:
        from ident.diagnosis.candidates import chunk_regression, delayed_regression_start

        reg = chunk_regression(chunk, shift=-m)
        return delayed_regression_start(chunk, 0, reg) if reg is not None else None

    def finish(self, spec, chunk, cfg):
        from ident.diagnosis.candidates import centre_delay

        return centre_delay(spec, chunk, cfg)

    def parameters(self, spec, Ts=None):
        # delay_s is the drive's dead time; a model whose delay also carries the lag of
        # sampling (sampling_lag) says how much, and simulates delay_s + sampling_lag_s
        lag = self.sampling_lag(spec, Ts) if Ts else 0.0
        out = {"delay_s": float(spec.ep[EP_INDEX["delay_s"]]) - lag,
               "where": _variants(self.name, "where")[int(spec.modes[MODE_SLOTS["time_delay"]])]}
        if "delay_s" in spec.ranges:
            out["delay_range_s"] = [float(v) - lag for v in spec.ranges["delay_s"]]
        if lag:
            out["sampling_lag_s"] = lag
        return out

    def set_arrays(self, p, ep, modes):
        ep[EP_INDEX["delay_s"]] = p["delay_s"] + p.get("sampling_lag_s", 0.0)
        modes[MODE_SLOTS["time_delay"]] = 1 if p.get("where") == _variants(self.name, "where")[1] else 0

    @staticmethod
    def sampling_lag(spec: ModelSpec, Ts: float) -> float:
        """The lag of a digital loop that ``spec``'s fitted delay carries besides the drive's
        dead time: Ts for a delay inside the loop on the continuous controller, 0 otherwise.

        A drive computes its output once a sample and holds it (half a sample of lag on
        average) from a velocity taken by backward difference (another half).  The sampled
        controller simulates both; the continuous one does not, and a dead time fitted
        inside its loop takes them up: on the independent bench's dead-time drives every
        fit on the continuous base came out 0.88–1.02 ms (one sample) above the truth
        (s1017.1, s1045.8, s5038.5), every fit on the sampled base within 0.15 ms of it
        (17 cases).  A capture delay lies outside the loop and carries no such lag.
        """
        return Ts if (spec.modes[MODE_SLOTS["time_delay"]] == 1 and not spec.sampled) else 0.0

    @classmethod
    def within_inherent_lag(cls, spec: ModelSpec, Ts: float) -> bool:
        """Is the dead time no longer than one sample period?  That much lag comes with
        sampling itself — the hold and backward-difference velocity of a digital loop, where
        in the servo cycle the position is read, recorded or the output applied — and a
        recording sampled every Ts cannot tell it from a drive's dead time.  The dead time
        is the fitted delay less the lag of sampling it carries (:meth:`sampling_lag`)."""
        return float(spec.ep[EP_INDEX["delay_s"]]) - cls.sampling_lag(spec, Ts) <= Ts

    def implausible(self, spec, chunk, cfg):
        return "delay within one sample period, the lag of sampling" if self.within_inherent_lag(spec, chunk.Ts) else ""

    def words(self, p, intervals=None, unresolved=None):
        # told in ms, the registry's delay_s (s) scaled for a reader of servo periods
        words = f"{self.called} {told(p, 'delay_s', '.2f', ' ms', intervals, unresolved, 1e3)} ({p['where']}"
        lag = p.get("sampling_lag_s", 0.0)
        if lag:
            words += (f"; the continuous-loop model delays by {1e3 * (p['delay_s'] + lag):.2f} ms, the "
                      f"{1e3 * lag:.2f} ms a digital loop's hold and sampled velocity add included")
        lo, hi = p.get("delay_range_s", (p["delay_s"], p["delay_s"]))
        if hi > 1.15 * lo:  # a weakly determined delay: say which ones fit as well
            words += f"; {1e3 * lo:.2f}–{1e3 * hi:.2f} ms fit equally well"
        return words + ")"

    def signature(self, loc):
        wh = loc.get("whiteness", {})
        return {"cross_correlation_peak": wh.get("cross_correlation_peak", 0.0),
                "lag_samples": wh.get("cross_correlation_peak_lag_samples", 0)}


class CyclicError(Effect):
    """A position-periodic error of the recorded position (mode 0, mm) or force (mode 1, mm/s²)."""

    name = REGISTRY["cyclic_error"].name
    added = 3
    scale_floor = {"amplitude_sin": 1e-4, "amplitude_cos": 1e-4}

    def free(self, spec):
        return ["period_mm", "amplitude_sin", "amplitude_cos"]

    def bounds(self, name, p0, chunk, cfg):
        return (0.7 * p0, 1.4 * p0) if name == "period_mm" else (-np.inf, np.inf)

    def starts(self, base, chunk, evidence, cfg):
        per = evidence.get("position_periodic", {})
        pg = evidence.get("position_periodogram_")
        cands: list[float] = []
        if pg is not None:  # the three strongest distinct periods of the position periodogram
            periods, share = pg
            for i in np.argsort(share)[::-1]:
                if all(abs(np.log(periods[i] / c)) > 0.1 for c in cands):
                    cands.append(float(periods[i]))
                if len(cands) >= 3:
                    break
        if not cands:
            cands = [per.get("period_mm") or 1.0]
        amp = max(per.get("amplitude_mm", 0.0), 1e-4)
        a2 = abs(base.theta[1]) or 1.0
        out = []
        for P in cands:
            for mode, a in ((0, amp), (1, a2 * amp)):
                # the phase is linear in the model: the best of four, base held, is start enough
                group = [base.with_effect(self.name, {"period_mm": P, "amplitude_sin": a * np.cos(ph),
                                                      "amplitude_cos": a * np.sin(ph)}, mode)
                         for ph in (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)]
                out.append(min(group, key=lambda s: sse(s, chunk)))
        return out

    def parameters(self, spec, Ts=None):
        ep = spec.ep
        kind = _variants(self.name, "kind")[int(spec.modes[MODE_SLOTS["cyclic_error"]])]
        c_s, c_c = ep[EP_INDEX["amplitude_sin"]], ep[EP_INDEX["amplitude_cos"]]
        return {"period_mm": float(ep[EP_INDEX["period_mm"]]), "amplitude": math.hypot(float(c_s), float(c_c)),
                "amplitude_unit": REGISTRY[self.name].parameter("amplitude").unit_by_variant[kind],
                "phase_rad": math.atan2(float(c_c), float(c_s)), "kind": kind}

    def set_arrays(self, p, ep, modes):
        ep[EP_INDEX["period_mm"]] = p["period_mm"]
        phase = p.get("phase_rad", 0.0)
        ep[EP_INDEX["amplitude_sin"]] = p["amplitude"] * math.cos(phase)
        ep[EP_INDEX["amplitude_cos"]] = p["amplitude"] * math.sin(phase)
        modes[MODE_SLOTS["cyclic_error"]] = 1 if p.get("kind") == _variants(self.name, "kind")[1] else 0

    def implausible(self, spec, chunk, cfg):
        # an error is periodic only where a whole period is seen (cfg.min_periods over the travel)
        period, travel = float(spec.ep[EP_INDEX["period_mm"]]), float(np.ptp(chunk.x))
        if period * cfg.min_periods > travel:
            return f"period {period:.3g} mm longer than the {travel:.3g} mm travel recorded"
        return ""

    def words(self, p, intervals=None, unresolved=None):
        return (f"{self.called}, period {self.said(p, 'period_mm', '.3g', intervals, unresolved)}, amplitude "
                f"{told(p, 'amplitude', '.3g', ' ' + shown_unit(p['amplitude_unit']), intervals, unresolved)}")

    def signature(self, loc):
        per = loc.get("position_periodic", {})
        return {"period_mm": per.get("period_mm", 0.0), "explained_share": per.get("explained_share", 0.0),
                "median_share": per.get("median_share", 0.0)}


class Saturation(Effect):
    """The control output clipped to ±limit, with (mode 0) or without (mode 1) anti-windup."""

    name = REGISTRY["saturation"].name
    added = 2
    #: an integral wound up while the output is clipped is a state no recording shows
    #: mid-move: a window restarted mid-move sets it to hold the recorded acceleration, so
    #: the variant without anti-windup ties with the frozen one there and loses the race it
    #: would win in free run (drive-zoo-dev2 case_003: 0.085 against 0.037 of the base's
    #: cost after the race on windows, 0.001 against 0.003 fitted in free run).  At a rest
    #: it is known (wound up beyond what friction holds, it would move the axis): its
    #: search races on windows restarted at rests (tests/test_diagnosis_windows.py)
    restartable = False
    #: 1/s: a slope started at 0 moves by steps of this scale; a viscous share of 1/s
    #: tilts the limit by 0.1 % of a 1000 mm/s² limit per mm/s
    scale_floor = {"limit_slope": 1.0}

    def free(self, spec):
        return ["limit", "limit_slope"]

    def bounds(self, name, p0, chunk, cfg):
        if name == "limit_slope":
            # a limit falling by more than ten times the largest acceleration over the top
            # speed is gone long before it: no limit the recording reached
            return 0.0, 10.0 * _amax(chunk) / _vmax(chunk)
        return 1e-3 * _amax(chunk), 100.0 * _amax(chunk)

    def starts(self, base, chunk, evidence, cfg):
        u = np.empty(chunk.n)
        simulate_spec(base, chunk, u_out=u)
        ok = np.isfinite(u)
        u, v = u[ok], chunk.derivs[0][ok]
        # ψ: the share of the position term that is the integral of the motor velocity —
        # 0 for a PID, about 0.8 for a P-PI cascade (it stops or runs on with the integral)
        psis = dict.fromkeys((0.0,) + motor_shares(base.theta))
        # the drive clips its own output, u + c·ẋ: eq. 3.3's u less the plant's viscous
        # share c of the speed term (a current limit on a plant with viscous friction, or a
        # voltage limit's back-EMF), so the limit of u falls with speed in the direction it
        # pushes.  c is invisible to eq. 3.3 (it sits in a1) until the clip bites: started
        # at 0 and where the limit falls by a quarter of itself at the top speed recorded
        c0 = float(np.percentile(np.abs(u), 99.0)) / _vmax(chunk)
        out = []
        for share in (0.0, 0.25):
            c = share * c0
            au = np.abs(u + c * v)
            out += [base.with_effect(self.name, {"limit": float(np.percentile(au, q)), "limit_slope": c,
                                                 "position_motor_share": psi}, w)
                    for q in (99.9, 99.0, 96.0) for psi in psis for w in (0, 1)]
        return out

    def parameters(self, spec, Ts=None):
        return {**_read(spec, "limit"), "limit_unit": REGISTRY[self.name].parameter("limit").unit,
                **_read(spec, "limit_slope", "position_motor_share"),
                "anti_windup": _variants(self.name, "anti_windup")[int(spec.modes[MODE_SLOTS["saturation"]])]}

    def set_arrays(self, p, ep, modes):
        ep[EP_INDEX["limit"]] = p["limit"]
        ep[EP_INDEX["limit_slope"]] = p.get("limit_slope", 0.0)
        ep[EP_INDEX["position_motor_share"]] = p.get("position_motor_share", ep[EP_INDEX["position_motor_share"]])
        modes[MODE_SLOTS["saturation"]] = _variants(self.name, "anti_windup").index(bool(p.get("anti_windup", True)))

    def words(self, p, intervals=None, unresolved=None):
        # the limit of the control-equivalent acceleration, not of an amplifier's volts
        slope = p.get("limit_slope", 0.0)
        return (f"saturation of the control-equivalent acceleration, limit "
                f"{self.said(p, 'limit', '.4g', intervals, unresolved)}"
                # the slope's unit, 1/s, told as what it is: mm/s² of limit per mm/s of speed
                + (f" at rest, falling by {told(p, 'limit_slope', '.3g', ' mm/s²', intervals, unresolved)} "
                   "per mm/s of speed" if slope > 0.0 else "")
                + ("" if p.get("anti_windup", True) else ", integral winding up while clipped"))

    def signature(self, loc):
        return {"high_acceleration_share": loc.get("high_acceleration_share", 0.0),
                "concentration": _concentration(loc, "high_acceleration_share", "high_acceleration_time_share")}


#: The effects of SPEC §7 by name, in the order of ``augmented.EFFECTS``.
EFFECT_MODELS: dict[str, Effect] = {e.name: e for e in (Backlash(), Stribeck(), Resonance(), TimeDelay(),
                                                         CyclicError(), Saturation())}


def effect_parameters(spec: ModelSpec, effect: str, Ts: float | None = None) -> dict:
    """The effect's parameters in the words of SPEC §7, with units in the key names; ``Ts``
    (the sample period) lets an effect tell them without what the sampling adds (a dead
    time without the lag of sampling its model carries, TimeDelay.sampling_lag)."""
    try:
        return EFFECT_MODELS[effect].parameters(spec, Ts)
    except KeyError:
        raise ValueError(f"unknown effect {effect!r}") from None
