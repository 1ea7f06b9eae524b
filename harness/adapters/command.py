"""The command adapter: any renderer with a command line.

    [[render]]
    adapter = "command"
    command = "{python} myrenderer.py --spp {spp} --seed {seed} --out {out}"
    exact = "ref.exr"              # an exact reference image (or reference_spp = N: rendered)
    reference_command = "..."      # optional: the reference's renderer (default: command)
    time = "stdout:took ([0-9.]+) s"   # optional: where the renderer reports its own time
    timeout = 600                  # seconds per render (default 3600)
    width = 64                     # optional: filled into {width} and {height}
    height = 64
    scene = "cornell"              # optional: what tables call the scene (default: the script)

The command runs in a shell in the suite file's folder, with ``{spp}``, ``{seed}`` (31 bits),
``{out}`` (a fresh path ending in ``.exr``, or ``.pfm``/``.hdr`` with ``format``), ``{width}``,
``{height}`` and ``{python}`` (the harness's own interpreter, so a script sees the same
packages) filled in (``{{`` and ``}}`` for literal braces).  The image it writes there is
read with OpenImageIO (EXR, PFM, HDR; float, (height, width, channels)).  A non-zero exit, a
timeout, a missing or unreadable image is a :class:`RenderError` naming the command and the
tail of its stderr; nothing is stored for that render.

Time.  A renderer's own timer, where it reports one: ``time = "stdout:<regex>"`` (the first
group of the first match, in seconds) or a JSON sidecar ``{out}.json`` holding ``seconds``;
else the process wall time minus a start-up time measured once, as the wall time of a 1-spp
render (it includes that one sample: a slight overestimate), stated in the table's notes.

Fingerprint.  The command, the keys above and the SHA-256 of every file the command names
(words that are files in the suite's folder, such as the script) and of the exact image: a
change of the renderer's source invalidates its stored renders.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from harness.adapters.base import (
    ENVIRONMENT,
    ExactImage,
    Render,
    RenderError,
    check_spec,
    file_digest,
    read_image,
)

__all__ = ["CommandRenderer", "make_renderer"]

_KEYS = {"command": str, "exact": str, "reference_command": str, "time": str, "timeout": (int, float),
         "width": int, "height": int, "scene": str, "format": str}
_FORMATS = ("exr", "pfm", "hdr")


class CommandRenderer:
    """A renderer run as a command per image (see the module docstring)."""

    def __init__(self, spec: dict[str, Any], base: Path):
        check_spec(spec, _KEYS, "command")
        if "command" not in spec:
            raise ValueError("'command': missing key: the command line that renders one image, with "
                             "{spp}, {seed} and {out}")
        self.spec, self.base = dict(spec), base
        self.command = spec["command"]
        self._check_placeholders(self.command, "command")
        self.format = spec.get("format", "exr")
        if self.format not in _FORMATS:
            raise ValueError(f"'format': expected one of: {', '.join(_FORMATS)}, got {self.format!r}")
        self.timeout = float(spec.get("timeout", 3600))
        if not self.timeout > 0:
            raise ValueError(f"'timeout': expected seconds > 0, got {self.timeout}")
        self.clock = spec.get("time", "")
        if self.clock and not self.clock.startswith("stdout:"):
            raise ValueError(f"'time': expected \"stdout:<regex>\" (the renderer's own time, in seconds, "
                             f"as the regex's first group), got {self.clock!r}")
        if self.clock:
            try:
                self.pattern = re.compile(self.clock[len("stdout:"):])
            except re.error as e:
                raise ValueError(f"'time': not a regular expression: {e}") from None
            if self.pattern.groups < 1:
                raise ValueError("'time': the regex needs a group capturing the seconds, "
                                 "e.g. \"took ([0-9.]+) s\"")
        self._exact = ExactImage(spec, base)
        self._startup: float | None = None

    def _check_placeholders(self, command: str, key: str) -> None:
        try:
            command.format(spp=1, seed=0, out="x", width=1, height=1, python="python")
        except (KeyError, IndexError, ValueError) as e:
            raise ValueError(f"'{key}': placeholders are {{spp}}, {{seed}}, {{out}}, {{width}}, {{height}}, "
                             f"{{python}} ({{{{ for a literal brace}}}}): {type(e).__name__} {e}") from None
        for needed in ("{spp}", "{seed}", "{out}"):
            if needed not in command:
                raise ValueError(f"'{key}': the command must contain {needed}")

    # --- the protocol ---------------------------------------------------------------------
    def render(self, spp: int, seed: int) -> Render:
        image, wall, own = self._run(self.command, spp, seed)
        if own is not None:
            return Render(image, spp, own)
        return Render(image, spp, max(wall - self.startup(), 0.0))

    def exact(self) -> np.ndarray | None:
        return self._exact.image()

    def reference(self) -> CommandRenderer:
        if "reference_command" not in self.spec:
            return self
        spec = {k: v for k, v in self.spec.items() if k not in ("reference_command", "exact")}
        spec["command"] = self.spec["reference_command"]
        return CommandRenderer(spec, self.base)

    def fingerprint(self) -> dict[str, Any]:
        """The table's keys and exact image; the digests of the files the command names are the
        environment (part of the store key, not of the seeds: an edited script is compared with
        the old one on the same seeds)."""
        files = {w: file_digest(self.base / w) for w in _words(self.command) if (self.base / w).is_file()}
        return {"adapter": "command", **{k: v for k, v in self.spec.items() if k != "exact"},
                "exact": self._exact.digest(), ENVIRONMENT: {"sources": files}}

    def describe(self) -> tuple[str, str]:
        """(scene, configuration) for tables: the ``scene`` key or the script the command runs,
        and the command itself."""
        scripts = [w for w in _words(self.command) if (self.base / w).is_file()]
        return self.spec.get("scene") or (Path(scripts[0]).name if scripts else "command"), self.command

    def notes(self) -> list[str]:
        """What a reader of the table must know: how the time was measured."""
        if self.clock:
            return [f"time: the renderer's own ({self.clock})"]
        startup = f"{self._startup:.3g} s" if self._startup is not None else "measured once per process"
        return [f"time: the renderer's own where it wrote {{out}}.json, else process wall time minus a "
                f"start-up time (the wall time of a 1-spp render: {startup})"]

    # --- running ----------------------------------------------------------------------------
    def startup(self) -> float:
        """Wall time (s) of a 1-spp render, measured once: what every render's wall time has
        in common (process start, scene loading)."""
        if self._startup is None:
            _, wall, _ = self._run(self.command, 1, 0)
            self._startup = wall
        return self._startup

    def _run(self, command: str, spp: int, seed: int) -> tuple[np.ndarray, float, float | None]:
        with tempfile.TemporaryDirectory(prefix="harness-render-") as folder:
            out = Path(folder) / f"image.{self.format}"
            line = command.format(spp=spp, seed=seed, out=shlex.quote(str(out)),
                                  python=shlex.quote(sys.executable), width=self.spec.get("width", ""),
                                  height=self.spec.get("height", ""))
            start = time.perf_counter()
            try:
                proc = _run_group(line, self.base, self.timeout)
            except subprocess.TimeoutExpired as e:
                raise RenderError(f"command {line!r} timed out after {self.timeout:g} s"
                                  + _tail(e.stderr)) from None
            wall = time.perf_counter() - start
            if proc.returncode != 0:
                raise RenderError(f"command {line!r} exited with status {proc.returncode}"
                                  + _tail(proc.stderr))
            if not out.is_file():
                raise RenderError(f"command {line!r} wrote no image at {{out}} = {out}" + _tail(proc.stderr))
            try:
                image = read_image(out).astype(np.float64)
            except OSError as e:
                raise RenderError(f"command {line!r}: {e}" + _tail(proc.stderr)) from None
            own = self._own_time(proc.stdout, out, line)
        return image, wall, own

    def _own_time(self, stdout: str, out: Path, line: str) -> float | None:
        if self.clock:
            m = self.pattern.search(stdout)
            if not m:
                raise RenderError(f"command {line!r}: its output has no match of time = {self.clock!r}"
                                  + _tail(stdout, "stdout"))
            return _seconds(m.group(1), line, "stdout")
        sidecar = out.with_name(out.name + ".json")
        if sidecar.is_file():
            try:
                return _seconds(json.loads(sidecar.read_text())["seconds"], line, str(sidecar.name))
            except (ValueError, KeyError, TypeError) as e:
                raise RenderError(f"command {line!r}: {{out}}.json must hold {{\"seconds\": <number>}}: "
                                  f"{type(e).__name__} {e}") from None
        return None


def make_renderer(spec: dict[str, Any], *, base: Path | None = None) -> CommandRenderer:
    """A renderer for a suite's ``[[render]] adapter = "command"`` table (see the module)."""
    return CommandRenderer(spec, (base or Path.cwd()).resolve())


def _words(command: str) -> list[str]:
    try:
        return shlex.split(command)
    except ValueError:
        return command.split()


def _seconds(value: Any, line: str, where: str) -> float:
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        raise RenderError(f"command {line!r}: its time in {where} is not a number: {value!r}") from None
    if not seconds >= 0:
        raise RenderError(f"command {line!r}: its time in {where} is negative or NaN: {value!r}")
    return seconds


def _tail(text: str | bytes | None, name: str = "stderr", lines: int = 8) -> str:
    if not text:
        return ""
    if isinstance(text, bytes):
        text = text.decode(errors="replace")
    tail = text.strip().splitlines()[-lines:]
    return f"; {name} ends:\n    " + "\n    ".join(tail) if tail else ""


def _run_group(line: str, cwd: Path | None, timeout: float) -> subprocess.CompletedProcess:
    """Runs a shell command line in its own process group, capturing its output; on a timeout
    or an interrupt (Ctrl-C, SIGTERM) the whole group is killed, so a renderer the shell
    started never outlives the run (``subprocess.run`` would kill only the shell).  Its output
    is read as UTF-8, a byte that is not (a progress bar's, a locale's) replaced: it had ended
    the run with a UnicodeDecodeError after a good render."""
    proc = subprocess.Popen(line, shell=True, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            encoding="utf-8", errors="replace", start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except BaseException:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return subprocess.CompletedProcess(line, proc.returncode, stdout, stderr)
