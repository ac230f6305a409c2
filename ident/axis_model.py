"""One identified axis as the virtual machine runs it: eq. 3.3 plus the effects the diagnosis accepted.

:class:`AxisModel` is the one model source of every prediction: the identification
fits and report, ``agent identify --against`` and the virtual machine
(``agent simulate --machine result.json``, ``agent predict``).  It holds

* the base parameters θ = (a1, a2, a3, b0, b1, b2, d0, d1) of eq. 3.3;
* the effects of SPEC §7 that the diagnosis accepted, by name, with the parameters in
  the words of :func:`ident.diagnosis.candidates.effect_parameters` (``gap_mm``, ``delay_s`` …),
  names, units and admissible ranges those of the effect registry (:mod:`core.effects`);
* the controller form the diagnosis fitted (``continuous`` eq. 3.3, ``sampled``: the
  control law evaluated once per sample and held, or ``sampled_causal``: the same with the
  feed-forward differentiating the command as the drive receives it);
* the preview shift of the identification (§4.3.2, samples the command is advanced by).

A plain model (no effects, continuous) is simulated by :func:`ident.simulation.simulate`,
the exact discretisation the identification fits with; any effect or the sampled form
by :func:`ident.diagnosis.augmented.simulate_augmented`, the simulator the diagnosis
fitted those effects with — so a prediction always uses the simulator its parameters
were fitted in.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np

from core.effect_limits import check_effect_parameters
from core.effects import EFFECT_NAMES, MODEL
from core.errors import InputError
from ident.model import BASE_KEYS, DriveModel, base_vector

__all__ = ["AxisModel", "BASE_KEYS", "EFFECT_NAMES", "CONTROLLERS"]

# EFFECT_NAMES (imported above from the effect registry, core.effects, re-exported): the
# SPEC §7 effects an axis model can carry (external_force is described, never simulated),
# in the order of the augmented simulator's flag vector.
#: The control law's forms, in the order of the augmented simulator's controller slot
#: (``modes[MODE_SLOTS["controller"]]``): eq. 3.3 as written, sampled and held, and sampled
#: with the feed-forward differentiating the command causally.
CONTROLLERS = ("continuous", "sampled", "sampled_causal")


@dataclass(frozen=True)
class AxisModel:
    """The closed-loop drive model of one axis, ready to simulate any command.

    Attributes
    ----------
    model : DriveModel
        Base parameters of eq. 3.3 (1/s, 1/s², 1/s³, –, 1/s, 1/s², mm/s², mm/s²).
    sample_period : float
        Controller sample period T_s, s, the model was identified at.
    shift : int
        Preview shift, samples (positive: command advanced), applied before simulating.
    effects : mapping effect name -> parameters
        Accepted SPEC §7 effects with their parameters (``{"backlash": {"gap_mm": 0.02, ...}}``).
    controller : str
        ``continuous``, ``sampled`` or ``sampled_causal`` (:data:`CONTROLLERS`).
    """

    model: DriveModel
    sample_period: float
    shift: int = 0
    effects: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    controller: str = "continuous"

    def __post_init__(self) -> None:
        unknown = set(self.effects) - set(EFFECT_NAMES)
        if unknown:
            raise InputError(f"unknown effect {sorted(unknown)[0]!r} (known: {', '.join(EFFECT_NAMES)})")
        if self.controller not in CONTROLLERS:
            raise InputError(f"controller {self.controller!r}: one of {', '.join(CONTROLLERS)}")
        if not self.sample_period > 0:
            raise InputError(f"sample period must be > 0 s, got {self.sample_period}")
        for name, params in self.effects.items():
            check_effect_parameters(name, params, complete=True, place=MODEL)

    # -- simulation ---------------------------------------------------------------------
    @property
    def plain(self) -> bool:
        """True for eq. 3.3 as identified: no effect, continuous control law."""
        return not self.effects and self.controller == "continuous"

    def simulate(self, x_r: np.ndarray, *, segment: np.ndarray | None = None,
                 x0: float | np.ndarray | None = None) -> np.ndarray:
        """Free-run actual position x̂ (mm) for the commanded ``x_r`` (mm, at ``sample_period``).

        ``segment`` (N,) restarts the state at each change; ``x0`` the start position
        (an array (N,): its value at each segment start, the recorded actual position, where
        the plain model starts as the identification fitted it, :mod:`ident.simulation`).
        ``x0`` None predicts from a standing machine: each segment starts at rest on the
        command with the integral at equilibrium, in both simulators, so a move predicted
        from 7 mm is the one from the origin shifted by 7 mm.
        """
        from ident.preprocessing import shift_command

        x_r = np.asarray(x_r, dtype=float)
        xs = shift_command(x_r, self.shift, segment) if self.shift else x_r
        if self.plain:
            from ident.simulation import simulate

            return simulate(self.model, xs, self.sample_period, segment=segment, x0=x0, at_rest=x0 is None)
        from ident.diagnosis.augmented import segment_starts, simulate_augmented

        n = x_r.size
        if x0 is None:
            start = x_r
        elif np.ndim(x0) == 0:
            start = np.full(n, float(x0))
        else:
            start = np.asarray(x0, dtype=float)
        theta, flags, ep, modes = self.spec_arrays()
        return simulate_augmented(xs, start, self.sample_period, theta, flags=flags, ep=ep, modes=modes,
                                  starts=segment_starts(n, segment))

    # -- the augmented simulator's arrays ----------------------------------------------
    def spec_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(θ, flags, ep, modes) in the layout of :mod:`ident.diagnosis.augmented`."""
        from ident.diagnosis.augmented import EFFECTS, MODE_SLOTS, N_EP, N_MODES
        from ident.diagnosis.effects import EFFECT_MODELS

        theta = base_vector(self.model)
        flags = np.array([1 if e in self.effects else 0 for e in EFFECTS], dtype=np.int64)
        ep = np.zeros(N_EP)
        modes = np.zeros(N_MODES, dtype=np.int64)
        modes[MODE_SLOTS["controller"]] = CONTROLLERS.index(self.controller)
        for name in EFFECTS:  # in the simulator's order: effects may share a slot (ψ)
            if name in self.effects:
                EFFECT_MODELS[name].set_arrays(self.effects[name], ep, modes)
        return theta, flags, ep, modes

    # -- edits and JSON ------------------------------------------------------------------
    def with_parameter(self, name: str, value: float) -> "AxisModel":
        """A copy with one base parameter (``a2``) or effect parameter (``backlash.gap_mm``) set."""
        if name in BASE_KEYS:
            return replace(self, model=replace(self.model, **{name: float(value)}))
        effect, _, key = name.partition(".")
        if effect in EFFECT_NAMES and key:
            effects = {e: dict(p) for e, p in self.effects.items()}
            effects.setdefault(effect, {})[key] = float(value)
            return replace(self, effects=effects)
        raise InputError(f"parameter {name!r}: a base parameter ({', '.join(BASE_KEYS)}) or EFFECT.KEY "
                         f"(e.g. backlash.gap_mm)")

    def to_dict(self) -> dict[str, Any]:
        return {
            "base": {k: float(getattr(self.model, k)) for k in BASE_KEYS},
            "sample_period_s": float(self.sample_period),
            "preview_shift_samples": int(self.shift),
            "controller": self.controller,
            "effects": {e: dict(p) for e, p in self.effects.items()},
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> "AxisModel":
        """Inverse of :meth:`to_dict`; a one-line InputError names what is missing."""
        try:
            base = doc["base"]
            model = DriveModel(**{k: float(base[k]) for k in BASE_KEYS})
            return cls(model=model, sample_period=float(doc["sample_period_s"]),
                       shift=int(doc.get("preview_shift_samples", 0)),
                       effects={str(e): dict(p) if isinstance(p, Mapping) else p  # checked as given
                                for e, p in dict(doc.get("effects") or {}).items()},
                       controller=str(doc.get("controller", "continuous")))
        except KeyError as exc:
            raise InputError(f"axis model has no {exc.args[0]!r}") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"axis model is malformed ({exc})") from None
