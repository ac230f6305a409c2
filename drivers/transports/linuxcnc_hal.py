"""LinuxCNC driver: sample HAL pins in the servo thread with ``sampler`` + ``halsampler``.

URL (SPEC §3)::

    linuxcnc://                         joint 0 as X
    linuxcnc://?joints=0,1&axes=X,Y
    linuxcnc://?joints=0&cmd=joint.{j}.motor-pos-cmd&fb=joint.{j}.motor-pos-fb

Options: ``joints`` (comma list, default 0), ``axes`` (names, default the letter of
XYZABCUVW at each joint number), ``cmd`` / ``fb`` (pin names, ``{j}`` = the joint number;
defaults ``joint.{j}.motor-pos-cmd`` and ``joint.{j}.motor-pos-fb``), ``running`` (a bit
pin true while a program runs; default ``halui.program.is-running``; ``running=`` for
none), ``end_idle`` (s the running pin must stay false after a program before the capture
ends; default 1.0, long enough for the gap between two programs run back to back),
``thread`` (default ``servo-thread``), ``depth`` (FIFO depth in samples, default 60000),
``scale`` (machine units → mm, every joint; default: read from the running LinuxCNC's INI,
below), ``channel`` (use FIFO N
of a ``sampler`` the HAL already loaded — only one sampler module can be loaded — instead
of loading one; its columns must be unlinked and typed as below).

Units: HAL's positions are in machine units, which the INI sets (``[TRAJ] LINEAR_UNITS``, mm
or inch).  Without ``scale=`` the driver reads the INI LinuxCNC was started with (its start
script exports ``INI_FILE_NAME`` to the processes it starts, ``rtapi_app`` among them): a
linear joint is recorded in mm (inches × 25.4), a joint of ``[JOINT_n] TYPE = ANGULAR`` in
degrees.  Where that INI cannot be read, positions are taken as mm.  The log's stream info
says which (``scale_to_mm`` per joint, ``units_from``).

It runs on the computer that runs LinuxCNC.  On open it loads LinuxCNC's ``sampler``
with one FIFO whose columns are each joint's commanded and actual position, the running
pin and ``sampler.0.overruns``; links each column to the signal that already carries the
pin (or, for an output pin on no signal, to a new ``rapid-ident-*`` signal), adds
``sampler.0`` at the end of the thread, and reads the FIFO with ``halsampler -t``.  It
never sets a pin, parameter or signal of the machine; on close it removes the function,
the links, its own signals and the module again, so the netlist is what it was.

Counting: halsampler's tag counts the samples *written* to the FIFO; a sample that finds
the FIFO full is lost and counted in ``sampler.0.overruns`` instead.  Sampling that pin
with the data makes ``counter = tag + overruns`` the servo period number, so every lost
period shows as a counter gap that the capture loop counts (docs/capture.md).

As root (LinuxCNC's ``rtapi_app`` refuses to run as root, so HAL belongs to another
user) ``halcmd`` and ``halsampler`` run as the user that owns ``rtapi_app``.
"""

from __future__ import annotations

import os
import pwd
import select
import shutil
import signal
import subprocess
from pathlib import Path

from core.errors import InputError, TransportError
from core.linuxcnc_ini import joint_unit, read_sections
from drivers.base import Driver, Sample, StreamInfo
from drivers.url import PortURL

__all__ = ["LinuxCNCDriver"]

_LETTERS = "XYZABCUVW"
_PREFIX = "rapid-ident-"  # names of the signals this driver creates (and deletes)


class LinuxCNCDriver(Driver):
    """Capture from the HAL of a running LinuxCNC; see the module docstring."""

    schemes = ("linuxcnc",)
    options = {"joints": str, "axes": str, "cmd": str, "fb": str, "running": str, "end_idle": float,
               "thread": str, "depth": int, "scale": float, "channel": int}

    def __init__(self, url: PortURL, axes: list[str] | None = None) -> None:
        super().__init__(url, axes)
        if url.host or url.path not in ("", "/"):
            raise InputError.about("port", f"{url.raw}: a linuxcnc URL has no host or path; "
                                   "use linuxcnc://?joints=0,1 on the LinuxCNC computer")
        try:
            self.joints = [int(j) for j in url.option("joints", str, "0").split(",")]
        except ValueError:
            raise InputError.about("port", f"{url.raw}: joints must be joint numbers, e.g. joints=0,1") from None
        if any(j < 0 for j in self.joints) or len(set(self.joints)) != len(self.joints):
            raise InputError.about("port", f"{url.raw}: joints must be distinct numbers >= 0")
        names = url.option("axes", str, None)
        if names is None:
            if any(j >= len(_LETTERS) for j in self.joints):
                raise InputError.about("port", f"{url.raw}: give axes= names for joints beyond {len(_LETTERS) - 1}")
            self.names = tuple(_LETTERS[j] for j in self.joints)
        else:
            self.names = tuple(a.strip() for a in names.split(","))
            if len(self.names) != len(self.joints) or not all(self.names):
                raise InputError.about("port", f"{url.raw}: axes= needs one name per joint ({len(self.joints)})")
        cmd = url.option("cmd", str, "joint.{j}.motor-pos-cmd")
        fb = url.option("fb", str, "joint.{j}.motor-pos-fb")
        self.pins = [p.replace("{j}", str(j)) for j in self.joints for p in (cmd, fb)]
        self.running_pin = url.option("running", str, "halui.program.is-running") or None
        self.running_given = "running" in url.query
        self.end_idle = url.option("end_idle", float, 1.0)
        self.thread = url.option("thread", str, "servo-thread")
        self.depth = url.option("depth", int, 60000)
        self.scale = url.option("scale", float, None)  # None: from the running LinuxCNC's INI
        self.channel = url.option("channel", int, None)
        if self.channel is not None and not 0 <= self.channel < 16:
            raise InputError.about("port", f"{url.raw}: channel must be a sampler FIFO number 0..15")
        self._ch = self.channel or 0
        if self.depth < 100 or not self.end_idle >= 0 or not (self.scale is None or self.scale > 0):
            raise InputError.about("port", f"{url.raw}: need depth >= 100, end_idle >= 0 and scale > 0")
        self._user: pwd.struct_passwd | None = None
        self._proc: subprocess.Popen | None = None
        self._buf = b""
        self._added: list[str] = []  # teardown steps done so far, in order
        self._own_signals: list[str] = []
        self._period = 0.0
        self._scales: list[float] = []  # per FIFO column: machine units -> mm (or deg)
        self._seen_running = False
        self._idle_samples = 0

    # -- HAL access --------------------------------------------------------------------
    def _child_kwargs(self) -> dict:
        if self._user is None:
            return {}
        env = dict(os.environ, HOME=self._user.pw_dir, USER=self._user.pw_name, LOGNAME=self._user.pw_name)
        return {"user": self._user.pw_uid, "group": self._user.pw_gid, "extra_groups": [], "env": env}

    def _hal(self, *args: str, check: bool = True) -> str:
        res = subprocess.run(["halcmd", "-s", *args], capture_output=True, text=True, timeout=30,
                             cwd="/", **self._child_kwargs())
        if check and res.returncode != 0:
            why = (res.stderr.strip() or res.stdout.strip()).splitlines()
            raise TransportError(f"halcmd {' '.join(args)} failed: {why[-1] if why else res.returncode}")
        return res.stdout

    def _pin(self, name: str) -> tuple[str, str, str] | None:
        """(type, direction, signal or "") of a HAL pin, None if it does not exist."""
        for line in self._hal("show", "pin", name).splitlines():
            f = line.split()
            if len(f) >= 5 and f[4] == name:
                sig = f[6] if len(f) >= 7 and f[5] in ("<==", "==>", "<=>") else ""
                return f[1], f[2], sig
        return None

    # -- open ------------------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        if shutil.which("halcmd") is None or shutil.which("halsampler") is None:
            raise TransportError("LinuxCNC is not installed here (no halcmd/halsampler on PATH); "
                                 "capture with linuxcnc:// on the computer that runs LinuxCNC")
        rtapi = _rtapi_processes()
        if not rtapi:
            raise TransportError("LinuxCNC is not running (no rtapi_app process); start LinuxCNC, then capture")
        owner = rtapi[0][1]  # the realtime master's user
        if os.geteuid() == 0 and owner != 0:
            self._user = pwd.getpwuid(owner)
        scales, units, units_from = self._joint_units(_running_ini(rtapi))
        self._scales = [f for f in scales for _ in (0, 1)]  # commanded and actual columns
        self._period = self._thread_period()
        pins = self._check_pins()
        cfg = "ff" * len(self.joints) + ("b" if self.running_pin else "") + "s"
        loaded = "sampler" in self._hal("list", "comp").split()
        if loaded and self.channel is None:
            if _PREFIX in self._hal("show", "sig"):
                raise TransportError("HAL still holds the sampler of a capture that did not close (killed?); "
                                     "remove it: halcmd unloadrt sampler, and halcmd delsig each rapid-ident-* signal")
            raise TransportError("HAL already has a sampler component loaded (only one can be); unload it "
                                 "(halcmd unloadrt sampler) or give a free FIFO of it with channel=N")
        if self.channel is not None:
            if not loaded:
                raise InputError.about("port", f"{self.url.raw}: channel= needs a loaded sampler; HAL has none")
            self._check_channel(cfg)
        try:
            self._setup(pins, cfg)
        except BaseException:
            self._teardown()
            raise
        return StreamInfo(
            axes=self.names,
            sample_period=self._period,
            controller=f"LinuxCNC (HAL sampler in {self.thread})",
            units=units,
            extra={"pins": self.pins, "running_pin": self.running_pin or "", "thread": self.thread,
                   "fifo_depth": self.depth, "scale_to_mm": scales, "units_from": units_from},
        )

    def _joint_units(self, ini: Path | None) -> tuple[list[float], tuple[str, ...], str]:
        """Per joint: the factor from machine units to the recorded unit, the unit ("mm" or
        "deg"), and where they come from (``scale=``, the INI, or the mm default)."""
        n = len(self.joints)
        if self.scale is not None:
            return [self.scale] * n, ("mm",) * n, "the port's scale= option"
        if ini is None:
            return [1.0] * n, ("mm",) * n, "default: mm (the INI LinuxCNC was started with was not found)"
        try:
            secs = read_sections(ini)
            per_joint = [joint_unit(secs, j, ini) for j in self.joints]
        except InputError as exc:
            return [1.0] * n, ("mm",) * n, f"default: mm ({exc})"
        return [k for k, _ in per_joint], tuple(u for _, u in per_joint), f"{ini}: [TRAJ] LINEAR_UNITS, [JOINT_n] TYPE"

    def _thread_period(self) -> float:
        for line in self._hal("show", "thread").splitlines():
            f = line.split()  # period_ns, FP, name, time, tmax, functions...
            if len(f) >= 3 and f[2] == self.thread:
                return int(f[0]) * 1e-9
        raise InputError.about("port", f"{self.url.raw}: HAL has no thread {self.thread!r}")

    def _check_pins(self) -> list[tuple[str, str, str, str]]:
        """[(pin, type, dir, signal)] of every pin to read; bad pins are one-line errors."""
        out = []
        wanted = list(self.pins) + ([self.running_pin] if self.running_pin else [])
        for name in wanted:
            info = self._pin(name)
            if info is None and name == self.running_pin and not self.running_given:
                self.running_pin = None  # no halui: the capture ends at --duration or Ctrl-C
                continue
            if info is None:
                raise InputError.about("port", f"{self.url.raw}: HAL has no pin {name!r}")
            kind, direction, sig = info
            need = "bit" if name == self.running_pin else "float"
            if kind != need:
                raise InputError.about("port", f"{self.url.raw}: pin {name!r} is {kind}, expected {need}")
            if direction != "OUT" and not sig:
                # linking an undriven input to a new signal would change what it reads
                raise InputError.about("port", f"{self.url.raw}: pin {name!r} is an input on no signal; "
                                       "nothing drives it, so there is nothing to record")
            out.append((name, kind, direction, sig))
        return out

    def _check_channel(self, cfg: str) -> None:
        """An existing FIFO must have exactly our column types, all unlinked."""
        types = {"float": "f", "bit": "b", "s32": "s"}
        have = []
        for col in range(len(cfg) + 1):
            info = self._pin(f"sampler.{self._ch}.pin.{col}")
            if info is None:
                break
            if info[2]:
                raise TransportError(f"sampler.{self._ch}.pin.{col} is already linked to {info[2]!r}; "
                                     "give a free channel=")
            have.append(types.get(info[0], "?"))
        if "".join(have) != cfg:
            raise InputError.about("port", f"{self.url.raw}: sampler FIFO {self._ch} has columns "
                                   f"{''.join(have) or 'none'}; this capture needs cfg={cfg}")

    def _setup(self, pins: list[tuple[str, str, str, str]], cfg: str) -> None:
        ch = f"sampler.{self._ch}"
        if self.channel is None:
            self._hal("loadrt", "sampler", f"depth={self.depth}", f"cfg={cfg}")
            self._added.append("module")
        self._added.append("links")
        for col, (name, _, _, sig) in enumerate(pins):
            if not sig:
                sig = f"{_PREFIX}{self._ch}-{col}"
                self._hal("net", sig, name)
                self._own_signals.append(sig)
            self._hal("net", sig, f"{ch}.pin.{col}")
        overruns = f"{_PREFIX}{self._ch}-overruns"
        self._own_signals.append(overruns)
        self._hal("net", overruns, f"{ch}.overruns", f"{ch}.pin.{len(pins)}")
        # its own session: a Ctrl-C on the terminal is for the capture, which then stops it
        self._proc = subprocess.Popen(["halsampler", "-c", str(self._ch), "-t"], stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, cwd="/",
                                      start_new_session=True, **self._child_kwargs())
        os.set_blocking(self._proc.stdout.fileno(), False)
        if not any(ch in line.split()[5:] for line in self._hal("show", "thread").splitlines()):
            self._hal("addf", ch, self.thread)
            self._added.append("function")

    # -- reading ---------------------------------------------------------------------------
    def _read(self, timeout: float) -> list[Sample]:
        fd = self._proc.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], timeout)
        if not ready:
            return []
        data = os.read(fd, 1 << 20)
        if not data:
            err = self._proc.stderr.read().decode(errors="replace").strip().splitlines()
            raise TransportError("halsampler stopped" + (f": {err[-1]}" if err else "")
                                 + " - did LinuxCNC shut down?")
        lines = (self._buf + data).split(b"\n")
        self._buf = lines.pop()
        out = []
        n = len(self.joints)
        for line in lines:
            f = line.split()
            if len(f) < 2 * n + 2:  # "overrun" notes and blank lines: losses show in the counter
                continue
            counter = int(f[0]) + int(f[-1])
            v = [float(x) * k for x, k in zip(f[1:1 + 2 * n], self._scales)]
            if self.running_pin:
                self._track_program(f[1 + 2 * n] == b"1")
            self.stats.received += 1
            out.append(Sample(counter=counter, t_s=counter * self._period, commanded=tuple(v[0::2]),
                              actual=tuple(v[1::2])))
        return out

    def _track_program(self, running: bool) -> None:
        """The end: ``end_idle`` s without a program after one ran.

        One segment throughout: the servo loop runs on between programs (its integrator
        too), so the recording is one continuous run with nothing to split.
        """
        self._seen_running = self._seen_running or running
        self._idle_samples = 0 if running else self._idle_samples + 1
        if self._seen_running and self._idle_samples * self._period >= self.end_idle:
            self.ended = True

    # -- close -----------------------------------------------------------------------------
    def _close(self) -> None:
        self._teardown()

    def _teardown(self) -> None:
        """Undo what _setup did, in reverse; keeps going past errors (LinuxCNC may be gone)."""
        ch = f"sampler.{self._ch}"
        if "function" in self._added:
            self._hal("delf", ch, self.thread, check=False)
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.send_signal(signal.SIGTERM)
                try:
                    self._proc.wait(5)
                except subprocess.TimeoutExpired:
                    self._proc.kill()
                    self._proc.wait(5)
            self._proc.stdout.close()
            self._proc.stderr.close()
            self._proc = None
        if "links" in self._added:
            for col in range(2 * len(self.joints) + 2):
                self._hal("unlinkp", f"{ch}.pin.{col}", check=False)
            self._hal("unlinkp", f"{ch}.overruns", check=False)
            for sig in self._own_signals:
                self._hal("delsig", sig, check=False)
        if "module" in self._added:
            self._hal("unloadrt", "sampler", check=False)
        self._added.clear()
        self._own_signals.clear()


def _rtapi_processes() -> list[tuple[int, int]]:
    """(pid, uid of its user) of every live ``rtapi_app`` (LinuxCNC's realtime process), oldest
    first: the first is the realtime master; ``halcmd loadrt`` starts short-lived ones beside it.

    rtapi_app is setuid root for realtime priorities: its real and effective uid may be 0,
    the file-system uid (the last of /proc's four) stays the user who started LinuxCNC.
    """
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/status") as f:
                status = f.read()
            with open(f"/proc/{entry}/stat") as f:
                started = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22: start time in ticks
        except (OSError, IndexError, ValueError):
            continue
        lines = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        if lines.get("Name", "").strip() == "rtapi_app" and lines.get("State", "").split()[:1] not in (["Z"], ["X"]):
            found.append((started, int(entry), int(lines["Uid"].split()[-1])))
    return [(pid, uid) for _, pid, uid in sorted(found)]


def _started_with_ini(pid: int) -> Path | None:
    """The INI file the process ``pid`` was started with (``INI_FILE_NAME`` in its
    environment, relative to its working directory), None if it has none or we may not read it."""
    try:
        with open(f"/proc/{pid}/environ", "rb") as f:
            env = dict(v.split(b"=", 1) for v in f.read().split(b"\0") if b"=" in v)
        name = env.get(b"INI_FILE_NAME")
        if not name:
            return None
        path = Path(os.fsdecode(name))
        if not path.is_absolute():
            path = Path(os.readlink(f"/proc/{pid}/cwd")) / path
    except OSError:
        return None
    return path if path.is_file() else None


def _running_ini(rtapi: list[tuple[int, int]]) -> Path | None:
    """The INI the running LinuxCNC was started with: from the oldest of the ``rtapi_app``
    processes ``rtapi`` (:func:`_rtapi_processes`) that has one."""
    for pid, _ in rtapi:
        ini = _started_with_ini(pid)
        if ini is not None:
            return ini
    return None
