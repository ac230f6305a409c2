"""The command line as a whole: one spelling per option, help that cites documents in the
repository, and what `agent serve` prints — through the real `agent` command."""

from __future__ import annotations

import os
import re
import select
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from agent.commands import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
AGENT = [sys.executable, "-m", "agent.cli"]


def agent(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "250"}  # help lines unwrapped, so a cited path stays whole
    return subprocess.run([*AGENT, *map(str, args)], capture_output=True, text=True, timeout=300, env=env)


@pytest.fixture(scope="module")
def program(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("prog")
    assert agent("generate", "--n-low", 10, "--n-high", 10, "-o", d).returncode == 0
    return d / "ident_low.nc"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_cites_documents_that_are_in_the_repository(command):
    proc = agent(command, "--help")
    assert proc.returncode == 0, proc.stderr
    assert "SPEC" not in proc.stdout  # the contract is docs/spec.md, not a document outside the repository
    for cited in re.findall(r"docs/[\w.-]+\.md", proc.stdout):
        assert (ROOT / cited).is_file(), cited


def test_the_contract_is_in_the_repository():
    spec = (ROOT / "docs/spec.md").read_text()
    for section in ("## 3. Command line", "## 4. Recordings", "## 6. JSON result", "## 7. Physics"):
        assert section in spec


@pytest.mark.parametrize("command, shown, hidden", [
    ("identify", "--axes", "--axis"),
    ("generate", "--centre", "--center"),
    ("ballbar", "--centre", "--center"),
])
def test_one_spelling_is_shown_and_the_other_still_works(command, shown, hidden, tmp_path):
    help_text = agent(command, "--help").stdout
    assert shown in help_text and not re.search(rf"{hidden}\b", help_text)
    if command == "generate":
        proc = agent("generate", hidden, "5", "--n-low", 10, "--n-high", 10, "-o", tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert "(center=5)" in (tmp_path / "ident_high.nc").read_text()
    else:  # the hidden spelling reaches the same check as the shown one
        bad = {"identify": [tmp_path / "absent.csv", hidden, "Q"], "ballbar": [hidden, "x", "--machine",
                                                                                tmp_path / "absent.json"]}[command]
        proc = agent(command, *bad)
        assert proc.returncode == 2 and "No such option" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("args, told", [
    (("identify",), "Missing argument 'log'"),
    (("identify", "rec.csv", "--json"), "Option '--json' requires an argument"),
    (("identify", "rec.csv", "--bogus"), "No such option: --bogus"),
    (("generate", "--n-low", "ten"), "Invalid value for '--n-low'"),
    (("frob",), "No such command 'frob'"),
])
def test_a_usage_error_is_one_error_line_with_exit_status_2(args, told):
    proc = agent(*args)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(f"error: {told}") and len(proc.stderr.splitlines()) == 1, proc.stderr


def test_agent_alone_prints_its_help():
    proc = agent()
    assert proc.returncode == 2 and "identify" in proc.stdout and proc.stderr == ""


def _lines_until(proc: subprocess.Popen, stream, wanted: str, timeout: float = 60) -> list[str]:
    """The lines of a pipe up to the first that starts with ``wanted`` (read from the raw file
    descriptor: a text wrapper's buffer would hide a second line that came with the first)."""
    end, text = time.monotonic() + timeout, ""
    while time.monotonic() < end:
        lines = text.splitlines()
        if any(ln.startswith(wanted) for ln in lines):
            return lines
        ready, _, _ = select.select([stream], [], [], 0.5)
        if ready:
            chunk = os.read(stream.fileno(), 4096)
            if not chunk:
                break
            text += chunk.decode()
        elif proc.poll() is not None:
            break
    raise AssertionError(f"no line starting {wanted!r} from agent serve: {text!r}")


def _serve(program: Path, transport: str) -> subprocess.Popen:
    return subprocess.Popen([*AGENT, "serve", str(program), "--transport", transport], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def test_serve_prints_the_port_quoted_for_the_shell(program):
    proc = _serve(program, "modbus")
    try:
        line = next(ln for ln in _lines_until(proc, proc.stdout, "port: ") if ln.startswith("port: "))
    finally:
        _stop(proc)
    assert line.startswith("port: '") and line.rstrip().endswith("'"), line
    (url,) = shlex.split(line[len("port: "):])  # what a shell makes of the pasted line: one word
    parts = urlsplit(url)
    assert parts.scheme == "modbus-tcp" and "mode=trace" in parts.query and "unit=1" in parts.query


def test_a_serial_endpoint_says_it_waits_for_a_client(program):
    proc = _serve(program, "serial")
    try:
        lines = _lines_until(proc, proc.stderr, "waiting for a client on ")
    finally:
        _stop(proc)
    waiting = [ln for ln in lines if ln.startswith("waiting for a client on /dev/pts/")]
    assert waiting, lines


def test_serve_warns_when_the_effects_make_the_simulated_loop_unstable(program):
    # a 50 ms dead time in a loop of ~50 Hz bandwidth: served all the same, said on stderr
    proc = subprocess.Popen([*AGENT, "serve", str(program), "--transport", "serial", "--effect", "time_delay=0.05"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = _lines_until(proc, proc.stderr, "waiting for a client on ")
    finally:
        _stop(proc)
    warned = [ln for ln in lines if ln.startswith("warning: X: the simulated axis does not follow the command")]
    assert len(warned) == 1, lines


@pytest.mark.parametrize("url, hint", [
    ("serial://dev/ttyUSB0", "serial:///dev/ttyUSB0"),
    ("modbus-rtu://dev/ttyUSB0?baud=115200", "modbus-rtu:///dev/ttyUSB0"),
])
def test_a_device_path_with_two_slashes_gets_the_three_slash_hint(tmp_path, url, hint):
    proc = agent("capture", "--port", url, "-o", tmp_path / "c.mcap")
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: --port:"), proc.stderr
    assert "'dev' would be read as a host name" in lines[0] and hint in lines[0]
    assert not (tmp_path / "c.mcap").exists()
