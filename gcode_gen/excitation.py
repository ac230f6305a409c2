"""Random point-to-point identification programs (thesis §3.3, Tables 3.2, 4.3, 4.4).

The rapid identification experiment runs "a series of NC instructions comprised of short
random linear movements" (thesis §3.3).  As in §4.3.3 two programs are generated and
their recordings concatenated:

* **low-speed set** — a random walk of ``n_low`` tiny steps.  Each step's magnitude is
  uniform in (0, ``low_step``] (default 0.03 mm, as the "travel distances up to 30 µm"
  of Table 4.3) with a random sign, so about half of the moves reverse direction and the
  drive is seen at the very low speeds met during motion reversals, where Coulomb
  friction dominates.  A triangular move of length d peaks at sqrt(a·d), i.e. below
  8 mm/s for 0.03 mm at 2000 mm/s².
* **high-speed set** — ``n_high`` targets drawn *uniformly* within centre ± range, as
  Table 3.2 (200 moves within ±10 mm).  With uniform targets the step length d = |x_k -
  x_(k-1)| has the triangular density 2(2R - d)/(2R)² on [0, 2R]: short and medium moves
  dominate, the peak speed sqrt(a·d) of a triangular profile spreads over the whole range
  and, with the thesis's defaults (200 mm/s, 2000 mm/s², R = 10 mm), the full feed needs
  v²/a = 20 mm = 2R, i.e. it is reached only when travelling from one end of the range to
  the other — the design rule of §3.3.  Two of every three consecutive moves of i.i.d.
  targets reverse direction.  The first two targets are the two ends of the range (as
  Table 4.4 starts with X-9.375, X+9.375), so the longest move is always present.
  ``distribution="loguniform"`` instead draws step lengths log-uniformly between
  ``low_step`` and 2R (equal numbers of moves per decade of length, hence per octave of
  peak speed); a step that would leave the range is reversed, and shortened to the far
  end of the range if it fits neither way.

Every target is quantised to the output resolution (10^-decimals mm) *before* it is
checked against the range, so the program text holds exactly the checked numbers and no
written target lies outside centre ± range.  Each program starts with a positioning move to
the centre (G01 at the maximum feed rather than the G00 of Tables 3.2/4.3/4.4, so that
no move of the program exceeds the feed limit) — the interpolator's default start is
that point, so in simulation it costs nothing.  The high-speed set ends with a feed move
back to the centre; the low-speed set ends where its walk ends, so that every one of its
feed moves (including the first, from the centre) stays within ``low_step``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from core.errors import InputError
from gcode_gen.program import AXIS_LETTERS, Block, Toolpath

__all__ = ["ExcitationSpec", "identification_programs", "low_speed_program", "high_speed_program"]

GENERATOR = "rapid-ident gcode_gen.excitation 1"


@dataclass(frozen=True)
class ExcitationSpec:
    """Parameters of the identification programs (all recorded in the program header).

    Attributes
    ----------
    axes : tuple[str, ...]
        Axis letters to excite (default ("X",)); with several, every block moves all of
        them together (independent random targets per axis).
    center : tuple[float, ...]
        Centre of the travel range per axis, mm.
    range_mm : float
        Half-width R of the travel range, mm: no target leaves centre ± R.
    low_step : float
        Largest step of the low-speed set, mm (0 < low_step <= R).
    n_low, n_high : int
        Number of random moves in the low- and high-speed sets (>= 1).
    feed : float
        Maximum (programmed) path feed, mm/s.
    seed : int
        Seed of the numpy Generator; the same spec gives the same programs.
    distribution : str
        High-speed set targets: "uniform" (thesis Table 3.2) or "loguniform" step lengths.
    decimals_low, decimals_high : int
        Decimal places written for each set (4 = 0.1 µm for the 0.03 mm steps).
    """

    axes: tuple[str, ...] = ("X",)
    center: tuple[float, ...] = (0.0,)
    range_mm: float = 10.0
    low_step: float = 0.03
    n_low: int = 200
    n_high: int = 200
    feed: float = 200.0
    seed: int = 1
    distribution: str = "uniform"
    decimals_low: int = 4
    decimals_high: int = 3

    def __post_init__(self) -> None:
        _validate(self)

    def header(self, set_name: str) -> dict[str, str]:
        """The ``key=value`` pairs written as comments at the top of each program."""
        return {
            "generator": GENERATOR,
            "program": f"identification {set_name}-speed set",
            "set": set_name,
            "axes": ",".join(self.axes),
            "center": ",".join(_fmt(c) for c in self.center),
            "range": _fmt(self.range_mm),
            "low_step": _fmt(self.low_step),
            "n_low": str(self.n_low),
            "n_high": str(self.n_high),
            "feed": _fmt(self.feed),
            "feed_units": "mm/s",
            "distribution": self.distribution,
            "decimals": str(self.decimals_low if set_name == "low" else self.decimals_high),
            "seed": str(self.seed),
        }


def _fmt(x: float) -> str:
    return format(float(x), ".12g")


def _validate(spec: ExcitationSpec) -> None:
    if not spec.axes:
        raise InputError("no axis given")
    for ax in spec.axes:
        if ax not in AXIS_LETTERS:
            raise InputError(f"unknown axis letter {ax!r} (use one of {''.join(AXIS_LETTERS)})")
    if len(set(spec.axes)) != len(spec.axes):
        raise InputError(f"axis given twice: {','.join(spec.axes)}")
    if len(spec.center) != len(spec.axes):
        raise InputError(f"{len(spec.center)} centre values for {len(spec.axes)} axes")
    for name, value, unit in (("range", spec.range_mm, "mm"), ("low-step", spec.low_step, "mm"), ("feed", spec.feed, "mm/s")):
        if not math.isfinite(value) or value <= 0:
            raise InputError(f"{name} must be a positive number of {unit}, got {value}")
    if any(not math.isfinite(c) for c in spec.center):
        raise InputError(f"centre must be finite, got {spec.center}")
    if spec.low_step > spec.range_mm:
        raise InputError(f"low-step {spec.low_step} mm is larger than the range {spec.range_mm} mm")
    for name, n in (("n-low", spec.n_low), ("n-high", spec.n_high)):
        if int(n) != n or n < 1:
            raise InputError(f"{name} must be an integer >= 1, got {n}")
    if spec.distribution not in ("uniform", "loguniform"):
        raise InputError(f"unknown distribution {spec.distribution!r} (uniform or loguniform)")
    for name, d in (("decimals_low", spec.decimals_low), ("decimals_high", spec.decimals_high)):
        if not 0 <= d <= 6:
            raise InputError(f"{name} must be 0..6, got {d}")
    res = 10.0 ** -spec.decimals_low
    if spec.low_step < res:
        raise InputError(f"low-step {spec.low_step} mm is below the output resolution {res} mm")


def _bounds_units(c: float, R: float, res: float) -> tuple[int, int, int]:
    """Centre and range ends in integer units of the resolution, rounded inwards."""
    lo = math.ceil((c - R) / res - 1e-9)
    hi = math.floor((c + R) / res + 1e-9)
    cu = min(max(round(c / res), lo), hi)
    return lo, cu, hi


def _to_mm(units: np.ndarray, decimals: int) -> np.ndarray:
    # np.round gives the double nearest the decimal string, so text -> float round-trips.
    return np.round(units * 10.0 ** -decimals, decimals)


def _low_walk(rng: np.random.Generator, spec: ExcitationSpec, c: float) -> np.ndarray:
    """Random walk of n_low steps, |step| uniform in (0, low_step], reflected at the range ends."""
    res = 10.0 ** -spec.decimals_low
    lo, cu, hi = _bounds_units(c, spec.range_mm, res)
    max_units = max(1, math.floor(spec.low_step / res + 1e-9))
    # magnitude uniform on the grid 1..max_units, i.e. in (0, low_step] at the output resolution
    mags = rng.integers(1, max_units, size=spec.n_low, endpoint=True)
    signs = np.where(rng.random(spec.n_low) < 0.5, -1, 1)
    units = np.empty(spec.n_low, dtype=np.int64)
    x = cu
    for k in range(spec.n_low):
        step = signs[k] * mags[k]
        if not lo <= x + step <= hi:
            step = -step  # reflect at the range end
        if not lo <= x + step <= hi:  # range narrower than the step both ways
            step = (hi - x) if signs[k] > 0 else (lo - x)
        x += int(step)
        units[k] = x
    return _to_mm(units, spec.decimals_low)


def _high_targets(rng: np.random.Generator, spec: ExcitationSpec, c: float) -> np.ndarray:
    """n_high targets within c ± R: the two range ends first, then random (see module doc)."""
    res = 10.0 ** -spec.decimals_high
    lo, cu, hi = _bounds_units(c, spec.range_mm, res)
    n = spec.n_high
    ends = np.array([lo, hi], dtype=np.int64)[: min(2, n)]
    m = n - len(ends)
    if spec.distribution == "uniform":
        rand = rng.integers(lo, hi, size=m, endpoint=True)
    else:
        d_min = max(spec.low_step, res) / res
        d_max = max(hi - lo, 1)
        lengths = np.maximum(1, np.round(np.exp(rng.uniform(math.log(d_min), math.log(d_max), m)))).astype(np.int64)
        signs = np.where(rng.random(m) < 0.5, -1, 1)
        rand = np.empty(m, dtype=np.int64)
        x = int(ends[-1]) if len(ends) else cu
        for k in range(m):
            step = signs[k] * lengths[k]
            if not lo <= x + step <= hi:
                step = -step
            if not lo <= x + step <= hi:
                step = (hi - x) if (hi - x) >= (x - lo) else (lo - x)
            x += int(step)
            rand[k] = x
    return _to_mm(np.concatenate([ends, rand]), spec.decimals_high)


def _centre_mm(c: float, spec: ExcitationSpec, decimals: int) -> float:
    res = 10.0 ** -decimals
    _, cu, _ = _bounds_units(c, spec.range_mm, res)
    return float(_to_mm(np.array([cu]), decimals)[0])


def _program(name: str, spec: ExcitationSpec, set_name: str, per_axis: list[np.ndarray], decimals: int,
             return_to_centre: bool) -> Toolpath:
    start = {ax: _centre_mm(c, spec, decimals) for ax, c in zip(spec.axes, spec.center)}
    # G01 at the maximum feed, not G00: a rapid would run at the machine's rapid rate and
    # break the feed limit the program promises (SPEC §8).
    blocks = [Block(line=0, n=None, motion="G1", target=dict(start), feed=float(spec.feed))]
    for k in range(len(per_axis[0])):
        target = {ax: float(per_axis[i][k]) for i, ax in enumerate(spec.axes)}
        blocks.append(Block(line=k + 1, n=None, motion="G1", target=target, feed=float(spec.feed)))
    if return_to_centre:
        blocks.append(Block(line=len(blocks), n=None, motion="G1", target=dict(start), feed=float(spec.feed)))
    return Toolpath(name=name, blocks=tuple(blocks), header=spec.header(set_name), decimals=decimals)


def low_speed_program(spec: ExcitationSpec, name: str = "ident_low") -> Toolpath:
    """The low-speed set: ``n_low`` random steps up to ``low_step`` mm (Table 4.3)."""
    rng = np.random.default_rng([spec.seed, 0])
    per_axis = [_low_walk(rng, spec, c) for c in spec.center]
    return _program(name, spec, "low", per_axis, spec.decimals_low, return_to_centre=False)


def high_speed_program(spec: ExcitationSpec, name: str = "ident_high") -> Toolpath:
    """The high-speed set: ``n_high`` random targets within centre ± range (Tables 3.2, 4.4)."""
    rng = np.random.default_rng([spec.seed, 1])
    per_axis = [_high_targets(rng, spec, c) for c in spec.center]
    return _program(name, spec, "high", per_axis, spec.decimals_high, return_to_centre=True)


def identification_programs(
    axes: Sequence[str] = ("X",),
    center: float | Sequence[float] = 0.0,
    range_mm: float = 10.0,
    low_step: float = 0.03,
    n_low: int = 200,
    n_high: int = 200,
    feed: float = 200.0,
    seed: int = 1,
    distribution: str = "uniform",
) -> tuple[Toolpath, Toolpath]:
    """Both identification programs (low-speed set, high-speed set).

    Parameters
    ----------
    axes : sequence of str
        Axis letters, e.g. ("X",) or ("X", "Y").
    center : float or sequence of float
        Centre of the travel range, mm; one value for all axes or one per axis.
    range_mm : float
        Half-width of the travel range, mm (default 10).
    low_step : float
        Largest low-speed step, mm (default 0.03).
    n_low, n_high : int
        Number of random moves per set (default 200 each).
    feed : float
        Maximum path feed, mm/s (default 200).
    seed : int
        Random seed (default 1).
    distribution : str
        "uniform" targets (default, Table 3.2) or "loguniform" step lengths.

    Raises
    ------
    InputError
        A parameter is out of range (one-line message naming it and its value).
    """
    axes = tuple(a.strip().upper() for a in axes)
    if isinstance(center, (int, float)):
        centers = tuple(float(center) for _ in axes)
    else:
        centers = tuple(float(c) for c in center)
        if len(centers) == 1:
            centers = centers * len(axes)
    spec = ExcitationSpec(
        axes=axes,
        center=centers,
        range_mm=float(range_mm),
        low_step=float(low_step),
        n_low=n_low,
        n_high=n_high,
        feed=float(feed),
        seed=int(seed),
        distribution=distribution,
    )
    return low_speed_program(spec), high_speed_program(spec)
