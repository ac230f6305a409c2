"""Mismatch diagnosis (issue 5, SPEC §6–7): locate where model and recording differ, name the
physics the model left out, model it, and show the held-out fit improve.

Modules: :mod:`.augmented` (eq. 3.3 plus each effect, numba free-run simulation),
:mod:`.residuals` (localisation and whiteness tests), :mod:`.candidates` (start grid and
output-error fit per effect), :mod:`.diagnose` (held-out scoring, verdict, words).
"""

from ident.diagnosis.augmented import EFFECTS
from ident.diagnosis.diagnose import Candidate, Diagnosis, diagnose

__all__ = ["EFFECTS", "Candidate", "Diagnosis", "diagnose"]
