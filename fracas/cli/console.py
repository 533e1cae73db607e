"""The terminal side of the command line: 80-column wrapping, one-line errors, the progress
display of a run's stages (rich, on stderr), and :class:`TerminalConsole`, the
:class:`fracas.modes.base.Console` every mode's command prints through.

Imports only click and the standard library at module import time, so help, version and a
deck's error answer without loading JAX, pydantic, h5py, rich or matplotlib.
"""

from __future__ import annotations

import re
import sys
import textwrap
from contextlib import contextmanager
from typing import Any

import click

# ----------------------------------------------------------------------------- 80 columns
# Terminal text wraps at word boundaries, never mid-word; a word longer than a line (a long
# path) stays whole on a line of its own, so it can be copied.  (textwrap only: an error
# must not wait for numpy or rich to import.)
WIDTH = 80


def _wrap(text: str, width: int = WIDTH, indent: str = "", more: str = "    ") -> list[str]:
    """``text`` as lines of at most ``width`` columns; continuation lines indented by
    ``indent + more``."""
    lines = textwrap.wrap(
        text,
        width,
        initial_indent=indent,
        subsequent_indent=indent + more,
        break_on_hyphens=False,
        break_long_words=False,
    )
    return [s if len(s) <= width else s.lstrip() for s in lines] or [indent.rstrip()]  # a long word: no indent


def _fill(text: str, width: int = WIDTH, indent: str = "", more: str = "    ") -> str:
    """:func:`_wrap` joined by newlines."""
    return "\n".join(_wrap(text, width, indent, more))


_VALUE_COLUMN = re.compile(r"^(\s*\S.*?\s{2,})\S")


def _fit_block(text: str, width: int = WIDTH) -> str:
    """Every line of ``text`` that is wider than ``width`` wrapped at word boundaries, its
    continuation lines indented under its value column (``label    value``: under
    ``value``; else 4 spaces past the line's own indentation).  Lines that fit are kept."""
    out = []
    for line in text.splitlines():
        if len(line) <= width:
            out.append(line)
            continue
        lead = line[: len(line) - len(line.lstrip())]
        m = _VALUE_COLUMN.match(line)
        hang = " " * len(m.group(1)) if m and len(m.group(1)) <= width // 2 else lead + "    "
        wrapped = textwrap.wrap(
            line.strip(),
            width,
            initial_indent=lead,
            subsequent_indent=hang,
            break_on_hyphens=False,
            break_long_words=False,
        )
        out += [s if len(s) <= width else s.lstrip() for s in wrapped]
    return "\n".join(out)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _stdout_is_terminal() -> bool:
    return _is_terminal(sys.stdout)


def _stderr_is_terminal() -> bool:
    return _is_terminal(sys.stderr)


_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _one_line(text: str) -> str:
    """``text`` with control characters (a newline in a file name) escaped, and characters
    that cannot be encoded (a file name that is not UTF-8) written as ``\\xNN``: one line."""
    text = text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), text)


def _say(text: str) -> None:
    """A line of the printout on stdout ("written: PATH", a one-line summary): wrapped to 80
    columns at word boundaries on a terminal; one line when piped (logs and scripts grep it)."""
    text = _one_line(text)
    click.echo(_fill(text) if _stdout_is_terminal() else text)


def _error_line(text: str) -> None:
    """An error on stderr: one line when stderr is not a terminal (logs, scripts: one line
    per problem to grep), wrapped to 80 columns with indented continuation lines on one."""
    text = _one_line(text)
    if _stderr_is_terminal():
        text = _fill(text)
    click.echo(text, err=True)


def _interrupted() -> None:
    click.echo("fracas: interrupted", err=True)
    sys.stderr.flush()


def _quiet_shutdown() -> None:
    """After an interrupt: Dask's and Tornado's loggers say nothing more (a cluster closing
    under Ctrl-C logs pages of warnings about the workers it is stopping)."""
    import logging

    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _early_interrupt(signum: int, frame: Any) -> None:
    """SIGINT before a command's own handling starts (imports, parsing): one line, exit 130
    (not click's "Aborted!" and exit 1)."""
    _interrupted()
    raise SystemExit(130)


class FracasGroup(click.Group):
    """The ``fracas`` group: an interrupt while Python and click start up ends as one inside
    a command does (:class:`_Interrupts`)."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return super().main(*args, **kwargs)
        previous = signal.signal(signal.SIGINT, _early_interrupt)
        try:
            return super().main(*args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, previous)


class _Interrupts:
    """While a command runs: the first SIGINT raises KeyboardInterrupt (as Python's default
    handler does) and is remembered; later ones are only remembered (the clean-up the first
    started is not cut short; a third ends the process at once).  A KeyboardInterrupt that
    Python could not raise (inside a ``__del__`` or a callback: "Exception ignored") is
    remembered, not printed.  The command then ends with one line and exit 130, however
    far its work got."""

    def __init__(self) -> None:
        self.count = 0
        self._saved: tuple[Any, Any] | None = None

    def _handler(self, signum: int, frame: Any) -> None:
        self.count += 1
        if self.count == 1:
            _quiet_shutdown()
            raise KeyboardInterrupt
        if self.count >= 3:
            import os

            _interrupted()
            os._exit(130)

    def _unraisable(self, info: Any) -> None:
        if issubclass(info.exc_type, KeyboardInterrupt):
            self.count = max(self.count, 1)
            _quiet_shutdown()
            return
        if self._saved is not None:
            self._saved[1](info)

    def __enter__(self) -> _Interrupts:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._saved = (signal.signal(signal.SIGINT, self._handler), sys.unraisablehook)
            sys.unraisablehook = self._unraisable
        return self

    def __exit__(self, *exc: object) -> None:
        if self._saved is None:
            return
        import signal

        signal.signal(signal.SIGINT, self._saved[0])
        sys.unraisablehook = self._saved[1]
        self._saved = None


@contextmanager
def _errors(debug: bool):
    """Map FracasError to one line + exit 2 (re-raise under --debug); an interrupt to one line
    + exit 130; a failing write (a full disk) to one line + exit 2.  The inputs the command
    reads are noted for its output checks (:func:`fracas.io.inputs.input_scope`)."""
    from fracas.errors import FracasError
    from fracas.io.inputs import input_scope, path_text

    interrupts = _Interrupts()
    try:
        with interrupts, input_scope():
            yield
    except FracasError as exc:
        if interrupts.count:
            _interrupted()
            sys.exit(130)
        if debug:
            raise
        _error_line(f"fracas: error: {exc}")
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        _interrupted()
        sys.exit(130)
    except (click.exceptions.Exit, click.ClickException, SystemExit):
        if interrupts.count:
            _interrupted()
            sys.exit(130)
        raise
    except OSError as exc:  # the system refused: a full disk, a permission; not a bug
        if interrupts.count:
            _interrupted()
            sys.exit(130)
        if debug:
            raise
        where = f"{path_text(exc.filename)}: " if exc.filename else ""
        _error_line(f"fracas: error: {where}{exc.strerror or exc}")
        sys.exit(2)
    except Exception as exc:  # a bug: say so briefly, the traceback is one flag away
        if interrupts.count:
            _interrupted()
            sys.exit(130)
        if debug:
            raise
        _error_line(f"fracas: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)")
        sys.exit(1)
    if interrupts.count:  # an interrupt swallowed where Python could not raise it
        _interrupted()
        sys.exit(130)


class _OneLineError(click.ClickException):
    """A bad option value as one line ``fracas: error: ...`` and exit 2 (not click's usage block)."""

    exit_code = 2

    def show(self, file: Any = None) -> None:
        _error_line(f"fracas: error: {self.message}")


def _utf8_name(text: str) -> None:
    """A file name that is not UTF-8 (``good\\xff.toml``) refused up front, in one line:
    results, provenance and reference decks record file names as UTF-8 text, and a run
    should not end in a file it cannot write."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        shown = _one_line(text)
        raise _OneLineError(
            f"{shown}: the file name is not UTF-8 text; expected a UTF-8 name (rename the file or its folder)"
        ) from None


class OutputFile(click.ParamType):
    """An output file option (``-o``, ``--plot``, ...): the value as the user wrote it is
    checked before click's Path would drop a trailing ``/`` or turn ``''`` into ``.``; an
    empty name, a name ending in ``/`` or an existing directory is one line, exit 2.  The
    rest of the checks are the orchestrator's (:func:`fracas.io.atomic.check_output_path`)."""

    name = "file"

    def __init__(self, what: str) -> None:
        self.what = what

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        from pathlib import Path

        if isinstance(value, Path):
            return value
        text = str(value)
        _utf8_name(text)
        if text.strip() in ("", ".", "..") or text.endswith("/") or Path(text).is_dir():
            from fracas.errors import OutputPathError
            from fracas.io.atomic import check_output_path

            try:
                check_output_path(text, self.what)
            except OutputPathError as exc:
                raise _OneLineError(str(exc)) from None
        return Path(text)


class InputFile(click.ParamType):
    """A file to read (a deck, --stm, a results file): a Path with a UTF-8 name; whether it
    can be read is the reader's one-line check."""

    name = "file"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        from pathlib import Path

        if isinstance(value, Path):
            return value
        _utf8_name(str(value))
        return Path(value)


def _duration(seconds: float) -> str:
    """12.3 s, 3 min 05 s, 1 h 02 min."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    m, s = divmod(int(round(seconds)), 60)
    if m < 60:
        return f"{m} min {s:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"


class _Stages:
    """The ``stage(text)`` callback of a command, as a rich progress display on stderr.

    Each call starts a new step: a spinner, what it is doing, a bar and ``done/total``
    once a count is known (``stage.count(done, total)``), and the step's elapsed time.  A
    step that took 2 s or more leaves a line with its duration.  While a step runs, every
    JAX compilation shows on its own line as ``compiling <function> (first run; cached
    afterwards)`` with its elapsed time (driven by JAX's compile log, which is captured
    here, never printed, and switched back off afterwards).  Off when ``enabled`` is false
    or stderr is not a terminal; ``plain`` then prints each step as one line on stderr.
    """

    LEAVE_S = 2.0

    def __init__(self, enabled: bool, plain: bool = False):
        self.progress = None
        self.task = None
        self.text = ""
        self.plain = False
        self._started = 0.0
        self._compile = None
        self._handler = None
        self._saved: dict = {}
        if not enabled:
            return
        from rich.console import Console

        console = Console(stderr=True)
        if not console.is_terminal:
            self.plain = plain
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
        from rich.table import Column

        class _IfCounted:
            def render(self, task):
                return super().render(task) if task.total is not None else ""

        class _Count(_IfCounted, MofNCompleteColumn):
            pass

        class _Bar(_IfCounted, BarColumn):
            pass

        self.progress = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}", table_column=Column(no_wrap=True, overflow="ellipsis", ratio=1)),
            _Bar(bar_width=16),
            _Count(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
            expand=True,
        )

    # -- steps
    def __call__(self, text: str) -> None:
        if self.plain:
            click.echo(text, err=True)
            return
        if self.progress is None:
            return
        self._watch_compiles()
        if text == self.text and self.task is not None:
            return
        import time

        self._finish_compile()
        self._finish()
        self.text = text
        self._started = time.monotonic()
        self.task = self.progress.add_task(text, total=None)

    def count(self, done: int, total: int | None) -> None:
        """The current step's count (``done`` of ``total``; None: not known yet)."""
        if self.progress is not None and self.task is not None:
            self.progress.update(self.task, completed=done, total=total)

    def _leave(self, text: str) -> None:
        from rich.text import Text

        self.progress.console.print(Text(text, style="dim"))

    def _finish(self) -> None:
        import time

        if self.task is None:
            return
        took = time.monotonic() - self._started
        self.progress.remove_task(self.task)
        self.task = None
        if took >= self.LEAVE_S:
            self._leave(f"{self.text} ({_duration(took)})")

    # -- JAX compilations (jax_log_compiles: "Compiling jit(f) ...", "Finished XLA compilation ...")
    def _compile_event(self, message: str) -> None:
        import re
        import time

        if self.progress is None:
            return
        m = re.match(r"Compiling (\w+)\(([^)]*)\)", message)
        if m:
            self._finish_compile()
            name = m.group(2) or m.group(1)
            task = self.progress.add_task(f"  compiling {name} (first run; cached afterwards)", total=None)
            self._compile = (task, name, time.monotonic())
        elif message.startswith("Finished XLA compilation"):
            self._finish_compile()

    def _finish_compile(self) -> None:
        import time

        if self._compile is None or self.progress is None:
            return
        task, name, t0 = self._compile
        self._compile = None
        self.progress.remove_task(task)
        took = time.monotonic() - t0
        if took >= self.LEAVE_S:
            self._leave(f"  compiled {name} ({_duration(took)}; cached for later runs)")

    def _watch_compiles(self) -> None:
        """Once JAX is imported: capture its compile log (not before: importing JAX here
        would slow commands that never use it; an environment variable would reach Dask
        workers, which would print the log)."""
        if self._handler is not None or "jax" not in sys.modules:
            return
        import logging

        import jax

        stages = self

        class _Handler(logging.Handler):
            def emit(self, record):
                try:
                    stages._compile_event(record.getMessage())
                except Exception:  # noqa: BLE001  (a display never breaks a run)
                    pass

        log = logging.getLogger("jax")
        self._handler = _Handler(level=logging.WARNING)
        self._saved = {"propagate": log.propagate, "log_compiles": bool(jax.config.jax_log_compiles)}
        log.addHandler(self._handler)
        log.propagate = False  # the compile log drives the display; it is not printed
        jax.config.update("jax_log_compiles", True)

    def __enter__(self):
        if self.progress is not None:
            self.progress.__enter__()
        return self

    def __exit__(self, *exc):
        if self.progress is None:
            return False
        self._finish_compile()
        self._finish()
        self.progress.__exit__(*exc)
        if self._handler is not None:
            import logging

            import jax

            log = logging.getLogger("jax")
            log.removeHandler(self._handler)
            log.propagate = self._saved["propagate"]
            jax.config.update("jax_log_compiles", self._saved["log_compiles"])
            self._handler = None
        return False


@contextmanager
def _progress(enabled: bool, plain: bool = False):
    """Yield a :class:`_Stages` callback (``stage(text)``, ``stage.count(done, total)``)."""
    with _Stages(enabled, plain) as stages:
        yield stages


class TerminalConsole:
    """The :class:`fracas.modes.base.Console` of the command line: stdout for the report,
    stderr for errors and the progress display."""

    def echo(self, text: str) -> None:
        click.echo(text)

    def say(self, text: str) -> None:
        _say(text)

    def fill(self, text: str, indent: str = "") -> str:
        return _fill(text, indent=indent)

    def error(self, text: str) -> None:
        _error_line(text)

    def progress(self, enabled: bool, plain: bool = False) -> Any:
        return _progress(enabled, plain)
