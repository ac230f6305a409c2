"""RS274/NGC parameters: numbered ``#1``–``#5602`` and named ``#<name>`` / ``#<_global>``.

Numbered parameters are global except ``#1``–``#30``, which a subroutine call saves, sets
to its arguments and restores on return.  Named parameters whose name starts with ``_``
are global; the others are local to the subroutine (or main program) that set them.
An unset numbered parameter reads 0 (as LinuxCNC without a parameter file); an unset
named one is an error.  LinuxCNC's numbers of the stored positions and offsets are used
(``#5161``–``#5169`` G28 position, ``#5181``–``#5189`` G30 position, ``#5211``–``#5219``
G92 offsets, ``#5220`` coordinate system, ``#5221 + 20·(n−1)`` + axis the offsets of
G54…G59.3) — here in mm, the virtual machine's unit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gcode_gen.ngc.expressions import ExprError

__all__ = ["Parameters", "MAX_PARAMETER", "G28_BASE", "G30_BASE", "G92_BASE", "COORD_SYSTEM", "G5X_BASE"]

MAX_PARAMETER = 5602
G28_BASE = 5161
G30_BASE = 5181
G92_BASE = 5211
COORD_SYSTEM = 5220
G5X_BASE = 5221


@dataclass
class Parameters:
    """The parameter store: numbered values, global named values, a stack of local scopes."""

    numbered: dict[int, float] = field(default_factory=dict)
    globals: dict[str, float] = field(default_factory=dict)
    scopes: list[dict[str, float]] = field(default_factory=lambda: [{}])

    def get(self, index: int) -> float:
        if not 1 <= index <= MAX_PARAMETER:
            raise ExprError(f"parameter number #{index} out of range 1..{MAX_PARAMETER}")
        return self.numbered.get(index, 0.0)

    def set(self, index: int, value: float) -> None:
        if not 1 <= index <= MAX_PARAMETER:
            raise ExprError(f"parameter number #{index} out of range 1..{MAX_PARAMETER}")
        self.numbered[index] = value

    def get_named(self, name: str) -> float:
        table = self.globals if name.startswith("_") else self.scopes[-1]
        if name not in table:
            raise ExprError(f"named parameter #<{name}> is not defined")
        return table[name]

    def exists(self, name: str) -> bool:
        return name in (self.globals if name.startswith("_") else self.scopes[-1])

    def set_named(self, name: str, value: float) -> None:
        (self.globals if name.startswith("_") else self.scopes[-1])[name] = value

    def enter(self, args: list[float]) -> dict[int, float]:
        """Start a subroutine: a new local scope, #1…#30 set to ``args`` (rest 0).

        Returns the caller's #1…#30 for :meth:`leave`.
        """
        saved = {i: self.numbered[i] for i in range(1, 31) if i in self.numbered}
        for i in range(1, 31):
            self.numbered[i] = args[i - 1] if i <= len(args) else 0.0
        self.scopes.append({})
        return saved

    def leave(self, saved: dict[int, float]) -> None:
        for i in range(1, 31):
            self.numbered.pop(i, None)
        self.numbered.update(saved)
        self.scopes.pop()
