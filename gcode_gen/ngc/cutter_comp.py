"""Cutter radius compensation G41/G42 in the XY (and XZ) plane, as LinuxCNC computes it.

A port of LinuxCNC's algorithm (interp_convert.cc ``convert_straight_comp1/2``,
``convert_arc_comp1/2``; interp_queue.cc): the tool centre runs one tool radius left (G41)
or right (G42) of the programmed path.

* **Entry** (first move after G41/G42): a line ends where a line from the current point
  is tangent to the tool circle at the programmed end; an arc ends one radius off the
  programmed arc's end, with its centre moved so it starts at the current point.
* **Convex corners**: an arc about the programmed corner joins the two offset paths
  (a G0 gets a straight traverse instead).
* **Concave corners**: the moves already queued get their end points moved back to where
  the two offset paths meet (line–line by the half corner angle, arc–line and arc–arc by
  circle intersections); a move that would have to run backwards is a gouge, an error.
* **Exit** (G40): the queue is flushed; the next move (a straight one) starts at the
  compensated point and ends at the programmed one.

The geometry is written for the plane's first and second axis (X, Y; in G18 Z, X) as
LinuxCNC's is.  Moves wait in a queue until the next move tells where they end; the queue is flushed
(``dequeue``) as LinuxCNC does.  Angles are compared with LinuxCNC's
TOLERANCE_CONCAVE_CORNER (0.05 rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["CutterComp", "QueuedMove", "LEFT", "RIGHT", "find_turn"]

LEFT, RIGHT = 1, 2
SMALL = 0.05  # TOLERANCE_CONCAVE_CORNER, rad
HALF_PI = math.pi / 2


def tool_inside_arc(side: int, turn: int) -> bool:
    return (side == LEFT and turn > 0) or (side == RIGHT and turn < 0)


def find_turn(x1: float, y1: float, cx: float, cy: float, turn: int, x2: float, y2: float) -> float:
    """Signed sweep (rad) of an arc from (x1, y1) to (x2, y2) about (cx, cy) with ``turn``."""
    if turn == 0:
        return 0.0
    alpha, beta = math.atan2(y1 - cy, x1 - cx), math.atan2(y2 - cy, x2 - cx)
    if turn > 0:
        if beta <= alpha:
            beta += 2 * math.pi
        return beta - alpha + (turn - 1) * 2 * math.pi
    if alpha <= beta:
        alpha += 2 * math.pi
    return beta - alpha + (turn + 1) * 2 * math.pi


@dataclass
class QueuedMove:
    """A compensated move waiting for its end point to be final (XY in mm, machine)."""

    kind: str  # "G0", "G1", "G2", "G3", "G4"
    x: float = 0.0
    y: float = 0.0
    rest: dict[str, float] = field(default_factory=dict)  # the other axes' targets
    dx: float = 0.0  # direction of the programmed motion (lines)
    dy: float = 0.0
    cx: float = 0.0  # arc centre and turn
    cy: float = 0.0
    turn: int = 0
    original_turns: float = 0.0
    feed: float | None = None
    dwell_s: float = 0.0
    line: int = 0
    n: int | None = None
    axes: tuple[str, str] = ("X", "Y")  # the plane's first and second axis (x, y above)
    plane: str = "XY"


class CompError(Exception):
    """Compensation cannot make this path (gouge, tool too large); the caller adds the line."""


class CutterComp:
    """Queue and geometry of cutter radius compensation; ``output`` receives finished moves."""

    def __init__(self, output: Callable[[QueuedMove], None]) -> None:
        self.output = output
        self.side = 0
        self.radius = 0.0
        self.firstmove = True
        self.queue: list[QueuedMove] = []
        self.endpoint = (0.0, 0.0)
        self.endpoint_valid = False
        self.program = (0.0, 0.0, 0.0)  # programmed (uncompensated) X, Y, Z

    @property
    def active(self) -> bool:
        return bool(self.side) and self.radius > 0.0

    # ---- queue --------------------------------------------------------------------------
    def dequeue(self) -> None:
        self.endpoint_valid = False
        for q in self.queue:
            self.output(q)
        self.queue.clear()

    def set_endpoint(self, x: float, y: float) -> None:
        self.endpoint = (x, y)
        self.endpoint_valid = True

    def enqueue(self, q: QueuedMove) -> None:
        if q.kind == "G4" and not self.queue:
            self.output(q)
            return
        self.queue.append(q)

    def move_endpoint_and_flush(self, x: float, y: float) -> None:
        for q in self.queue:
            if q.kind in ("G2", "G3"):
                r1 = math.hypot(q.x - q.cx, q.y - q.cy)
                r2 = math.hypot(x - q.cx, y - q.cy)
                l2 = find_turn(self.endpoint[0], self.endpoint[1], q.cx, q.cy, q.turn, x, y)
                if abs(r1 - r2) > 0.01 * 25.4:
                    raise CompError(f"cutter compensation made an arc with radii {r1:.4f} and {r2:.4f} mm")
                # A gouge flips the arc round (several rad more); LinuxCNC 2.9's rs274 lets overruns of
                # a few mrad pass (measured up to 3.5 mrad), so the margin is 0.254 rad as in
                # LinuxCNC-derived interpreters, not the 0.001 of LinuxCNC's current source.
                if q.original_turns and self.endpoint_valid and abs(l2) > abs(q.original_turns) + 0.254:
                    raise CompError(f"arc move in a concave corner cannot be reached by the tool without gouging "
                                    f"(it would sweep {abs(l2):.4f} rad, the programmed arc {abs(q.original_turns):.4f})")
                q.x, q.y = x, y
            elif q.kind in ("G0", "G1"):
                dot = q.dx * (x - self.endpoint[0]) + q.dy * (y - self.endpoint[1])
                if self.endpoint_valid and dot < 0:
                    raise CompError("straight move in a concave corner cannot be reached by the tool without gouging")
                q.x, q.y = x, y
        self.dequeue()
        self.set_endpoint(x, y)

    # ---- on / off -----------------------------------------------------------------------
    def start(self, side: int, radius: float, program: tuple[float, float, float]) -> None:
        if self.side:
            raise CompError("cutter radius compensation is already on (G40 first)")
        if radius < 0:
            radius, side = -radius, (LEFT if side == RIGHT else RIGHT)
        self.side, self.radius, self.firstmove = side, radius, True
        self.program = program

    def stop(self, current: tuple[float, float]) -> bool:
        """G40; returns True when the current point jumps back to the programmed one."""
        was = self.active
        if was:
            self.move_endpoint_and_flush(*current)
            self.dequeue()
        self.side, self.firstmove = 0, True
        return was

    # ---- straight moves -----------------------------------------------------------------
    def straight(self, kind: str, cur: tuple[float, float, float], p: tuple[float, float, float],
                 make: Callable[..., QueuedMove]) -> tuple[float, float, float]:
        """Compensated straight move to programmed ``p`` from tool position ``cur``; returns the
        new tool position.  ``make(kind, x, y, z, dx, dy)`` builds the queued move."""
        cx, cy, _ = cur
        px, py, pz = p
        r = self.radius
        if self.firstmove:
            # LinuxCNC refuses <= r; in its float arithmetic an entry exactly one radius long
            # (useful-subroutines.ngc) passes, so only a shorter one is refused here.
            if math.hypot(px - cx, py - cy) < r - 1e-9:
                raise CompError("the cutter compensation entry move is shorter than the tool radius")
            alpha = math.atan2(py - cy, px - cx) + (HALF_PI if self.side == LEFT else -HALF_PI)
            ex, ey = px + r * math.cos(alpha), py + r * math.sin(alpha)
            self.set_endpoint(cx, cy)
            self.enqueue(make(kind, ex, ey, pz, math.cos(alpha), math.sin(alpha)))
            self.firstmove = False
            self.program = p
            return ex, ey, pz
        opx, opy, opz = self.program
        if py == opy and px == opx:  # no XY motion
            self.enqueue(make(kind, cx, cy, pz, 0.0, 0.0))
            self.program = p
            return cx, cy, pz
        theta = math.atan2(cy - opy, cx - opx)
        alpha = math.atan2(py - opy, px - opx)
        if self.side == LEFT:
            if theta < alpha:
                theta += 2 * math.pi
            beta, gamma = theta - alpha - HALF_PI, HALF_PI
        else:
            if alpha < theta:
                alpha += 2 * math.pi
            beta, gamma = alpha - theta - HALF_PI, -HALF_PI
        ex, ey = px + r * math.cos(alpha + gamma), py + r * math.sin(alpha + gamma)
        mid_x, mid_y = opx + r * math.cos(alpha + gamma), opy + r * math.sin(alpha + gamma)
        front = self.queue[0] if self.queue else None
        if beta < -SMALL or beta > math.pi + SMALL:
            concave = True
        elif (beta > math.pi - SMALL and front is not None and front.kind in ("G2", "G3")
              and ((self.side == RIGHT and front.turn > 0) or (self.side == LEFT and front.turn < 0))):
            concave = True  # the "h" shape: stay above and right
        else:
            concave = False
        if not concave and beta > SMALL:  # convex: an arc (a traverse for G0) round the corner
            self.move_endpoint_and_flush(cx, cy)
            if kind == "G1":
                self.enqueue(make("G2" if self.side == LEFT else "G3", mid_x, mid_y, cur[2], 0.0, 0.0,
                                  centre=(opx, opy), turn=-1 if self.side == LEFT else 1))
            else:
                self.enqueue(make("G0", mid_x, mid_y, cur[2], 0.0, 0.0))
            self.dequeue()
            self.set_endpoint(mid_x, mid_y)
        elif concave:
            if front is None or front.kind not in ("G2", "G3"):  # line -> line
                halfcorner = (beta + math.pi) / 2.0
                if halfcorner == 0.0:
                    raise CompError("a zero-degree inside corner is invalid for cutter compensation")
                retreat = r / math.tan(halfcorner)
                self.move_endpoint_and_flush(cx + retreat * math.cos(theta + gamma), cy + retreat * math.sin(theta + gamma))
            else:  # arc -> line
                prev = front
                oldrad = math.hypot(prev.cy - prev.y, prev.cx - prev.x)
                base_dir = math.atan2(py - opy, px - opx)
                th = base_dir + HALF_PI if prev.turn > 0 else base_dir - HALF_PI
                phi = math.atan2(prev.cy - opy, prev.cx - opx)
                inside = tool_inside_arc(self.side, prev.turn)
                oldrad_uncomp = oldrad + r if inside else oldrad - r
                d = oldrad_uncomp * math.cos(th - phi)
                l = (d - r) / oldrad if inside else (d + r) / oldrad
                if not -1.0 <= l <= 1.0:
                    raise CompError("arc to straight motion makes a corner the compensated tool cannot fit in without gouging")
                sign = 1.0 if (prev.turn > 0) != inside else -1.0
                angle = sign * math.acos(l) + th + math.pi
                self.move_endpoint_and_flush(prev.cx + oldrad * math.cos(angle), prev.cy + oldrad * math.sin(angle))
        else:  # colinear, or tangent arc -> line
            self.dequeue()
            self.set_endpoint(cx, cy)
        self.enqueue(make(kind, ex, ey, pz, px - opx, py - opy))
        self.program = p
        return ex, ey, pz

    # ---- arcs ---------------------------------------------------------------------------
    def arc(self, kind: str, cur: tuple[float, float, float], p: tuple[float, float, float],
            centre_of: Callable[[float, float], tuple[float, float]], turns: int,
            make: Callable[..., QueuedMove]) -> tuple[float, float, float]:
        """Compensated arc to programmed ``p``; ``centre_of(start_x, start_y)`` gives the
        programmed centre for an arc starting there (I/J relative to the start, or R)."""
        cx, cy, cz = cur
        ex, ey, ez = p
        r = self.radius
        turn = (1 if kind == "G3" else -1) * turns
        side = self.side
        if self.firstmove:
            if math.hypot(ex - cx, ey - cy) < r - 1e-9:
                raise CompError("the cutter compensation entry arc ends closer than the tool radius")
            ccx, ccy = centre_of(cx, cy)
            if math.hypot(ccx - cx, ccy - cy) < r - 1e-9 and tool_inside_arc(side, turn):
                raise CompError("tool radius not less than the arc radius with compensation")
            if tool_inside_arc(side, turn):
                gamma = math.atan2(ccy - ey, ccx - ex)
            else:
                gamma = math.atan2(ey - ccy, ex - ccx)
            self.firstmove = False
            self.program = p
            nx, ny = ex + r * math.cos(gamma), ey + r * math.sin(gamma)
            b_len = math.hypot(cy - ny, cx - nx) / 2.0
            ab_ang = math.atan2(ccy - ny, ccx - nx)
            a_ang = math.atan2(cy - ny, cx - nx) - ab_ang
            if abs(math.cos(a_ang)) < 1e-4:
                raise CompError("tool radius not less than the arc radius with compensation")
            c_len = b_len / math.cos(a_ang)
            kx, ky = nx + c_len * math.cos(ab_ang), ny + c_len * math.sin(ab_ang)
            self.enqueue(make(kind, nx, ny, ez, 0.0, 0.0, centre=(kx, ky), turn=turn,
                              original=find_turn(cx, cy, kx, ky, turn, nx, ny)))
            return nx, ny, ez
        opx, opy, opz = self.program
        ccx, ccy = centre_of(opx, opy)
        arc_radius = math.hypot(ccx - ex, ccy - ey)
        theta = math.atan2(cy - opy, cx - opx)
        theta = theta - HALF_PI if side == LEFT else theta + HALF_PI
        delta = math.atan2(ccy - opy, ccx - opx)
        alpha = delta - HALF_PI if kind == "G3" else delta + HALF_PI
        beta = theta - alpha if side == LEFT else alpha - theta
        if beta > 1.5 * math.pi:
            beta -= 2 * math.pi
        elif beta < -HALF_PI:
            beta += 2 * math.pi
        inside = tool_inside_arc(side, turn)
        if inside:
            gamma = math.atan2(ccy - ey, ccx - ex)
            if arc_radius < r - 1e-9:  # LinuxCNC: <=, but equal passes in its float arithmetic
                raise CompError("tool radius not less than the arc radius with compensation")
        else:
            gamma = math.atan2(ey - ccy, ex - ccx)
            delta += math.pi
        nx, ny = ex + r * math.cos(gamma), ey + r * math.sin(gamma)
        original = find_turn(opx, opy, ccx, ccy, turn, ex, ey)
        front = self.queue[0] if self.queue else None
        if beta < -SMALL or beta > math.pi + SMALL or (abs(beta - math.pi) < SMALL and not inside):  # concave
            if front is None or front.kind not in ("G2", "G3"):  # line -> arc
                c_y = arc_radius * math.sin(beta - HALF_PI)
                if inside:
                    dist = arc_radius - r
                    l = (c_y + r) / dist
                    if not -1.0 <= l <= 1.0:
                        raise CompError("arc move in a concave corner cannot be reached by the tool without gouging")
                    ang = theta + math.asin(l) if turn > 0 else theta - math.asin(l)
                else:
                    dist = arc_radius + r
                    l = (c_y - r) / dist
                    if not -1.0 <= l <= 1.0:
                        raise CompError("arc move in a concave corner cannot be reached by the tool without gouging")
                    ang = theta + math.pi - math.asin(l) if turn > 0 else theta + math.pi + math.asin(l)
                self.move_endpoint_and_flush(ccx + dist * math.cos(ang), ccy + dist * math.sin(ang))
            else:  # arc -> arc
                prev = front
                oldrad = math.hypot(prev.cy - prev.y, prev.cx - prev.x)
                newrad = arc_radius - r if inside else arc_radius + r
                arc_cc = math.hypot(prev.cy - ccy, prev.cx - ccx)
                if oldrad == 0 or arc_cc == 0:
                    raise CompError("arc to arc motion is invalid because the arcs have the same centre")
                a = (oldrad ** 2 + arc_cc ** 2 - newrad ** 2) / (2 * oldrad * arc_cc)
                if not -1.0 <= a <= 1.0:
                    raise CompError("arc to arc motion makes a corner the compensated tool cannot fit in without gouging")
                pullback = math.acos(a)
                cc_dir = math.atan2(ccy - prev.cy, ccx - prev.cx)
                if tool_inside_arc(side, prev.turn):
                    direction = cc_dir + pullback if turn > 0 else cc_dir - pullback
                else:
                    direction = cc_dir - pullback if turn > 0 else cc_dir + pullback
                self.move_endpoint_and_flush(prev.cx + oldrad * math.cos(direction), prev.cy + oldrad * math.sin(direction))
        elif beta > SMALL:  # convex: an arc round the corner first
            mid_x, mid_y = opx + r * math.cos(delta), opy + r * math.sin(delta)
            self.dequeue()
            self.enqueue(make("G2" if side == LEFT else "G3", mid_x, mid_y, cz, 0.0, 0.0, centre=(opx, opy),
                              turn=-1 if side == LEFT else 1))
            self.dequeue()
            self.set_endpoint(mid_x, mid_y)
        else:
            self.dequeue()
            self.set_endpoint(cx, cy)
        self.enqueue(make(kind, nx, ny, ez, 0.0, 0.0, centre=(ccx, ccy), turn=turn, original=original))
        self.program = p
        return nx, ny, ez
