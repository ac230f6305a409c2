"""Tuning on the virtual machine (issue 42): from the identified closed loop to the plant,
then gains that minimise a predicted figure within stated margins.  docs/tuning.md.

Modules: :mod:`.loop` (the sampled position loop), :mod:`.controllers` (forms, gains,
eq. 3.4/3.5), :mod:`.plant` (closed loop → plant), :mod:`.margins`, :mod:`.figures`
(predicted circularity / contour error), :mod:`.optimise` (the search), :mod:`.ini`
(LinuxCNC INI read and diff), :mod:`.proposal` (:func:`tune`).
"""

from ident.tuning.controllers import CONTROLLER_FORMS, Gains, closed_loop
from ident.tuning.figures import Criterion
from ident.tuning.margins import Margins, margins
from ident.tuning.plant import Plant, derive_plant, match_coefficients
from ident.tuning.proposal import Tuning, TuningRefused, tune

__all__ = ["CONTROLLER_FORMS", "Gains", "closed_loop", "Criterion", "Margins", "margins", "Plant", "derive_plant",
           "match_coefficients", "Tuning", "TuningRefused", "tune"]
