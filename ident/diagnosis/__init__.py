"""Mismatch diagnosis (issue 5, SPEC §6–7): locate where model and recording differ, name the
physics the model left out, model it, and show the held-out fit improve.

Modules: :mod:`.augmented` (eq. 3.3 plus each effect, numba free-run simulation),
:mod:`.spec` (a candidate model and its cost), :mod:`.effects` (one object per effect),
:mod:`.config` (the tunables), :mod:`.residuals` (localisation and whiteness tests),
:mod:`.disturbance` (the equivalent input disturbance), :mod:`.candidates` (the one search
every effect is fitted by), :mod:`.diagnose` (held-out scoring, verdict, words).
"""

from ident.diagnosis.augmented import EFFECTS
from ident.diagnosis.config import DiagnosisConfig
from ident.diagnosis.diagnose import Candidate, Diagnosis, diagnose
from ident.diagnosis.effects import EFFECT_MODELS

__all__ = ["EFFECTS", "EFFECT_MODELS", "Candidate", "Diagnosis", "DiagnosisConfig", "diagnose"]
