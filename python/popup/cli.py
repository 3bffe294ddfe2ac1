"""``popup``: the package's one command line.

``pip install`` puts a single ``popup`` on ``PATH`` (this module's :func:`main`; also
``python -m popup``). It routes each subcommand to where it is implemented:

* Python subcommands (:data:`PYTHON_COMMANDS`, e.g. ``popup diagnose``) run
  ``cli_main(args) -> int`` of their module (``popup diagnose``: :mod:`popup.diagnosis`),
  imported only when called;
* everything else, including ``--version`` and unknown names, goes to the Rust CLI
  (``popup_cli::run_from_args`` through :func:`popup._core.run_cli`): ``info``, ``arm``,
  ``statics``, ``hold``, ... with their options, messages and exit codes unchanged
  (0 ok, 2 usage error or failed command);
* ``popup``, ``popup -h``/``--help`` and ``popup help`` print one help listing both.

The exit code of the subcommand is returned by :func:`main` and becomes the process's.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os
import re
import signal
import sys
import tempfile
import threading
from typing import Callable, Dict, Iterator, List, Optional, Sequence, TextIO, Tuple

PROG = "popup"

#: Python subcommands: name -> (module with ``cli_main(args: list[str]) -> int``, summary).
PYTHON_COMMANDS: Dict[str, Tuple[str, str]] = {
    "diagnose": ("popup.diagnosis", "Diagnose where and why the model departs from a measured run"),
}

_HELP = ("-h", "--help")

#: Rust commands that install their own SIGINT/SIGTERM handling (they finish their logs).
SIGNAL_AWARE = ("run", "sweep")


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``popup`` on ``argv`` (default ``sys.argv[1:]``) and return the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        # like the Rust CLI without a subcommand: a usage error, but with the full list
        print_help(sys.stderr)
        return 2
    cmd, rest = args[0], args[1:]
    if cmd in _HELP or (cmd == "help" and not rest):
        print_help(sys.stdout)
        return 0
    if cmd == "help" and rest[0] in PYTHON_COMMANDS:
        return _run_python(rest[0], ["--help"])
    if cmd in PYTHON_COMMANDS:
        return _run_python(cmd, rest)
    if cmd == "sweep" and "--parquet" in rest:
        return _sweep_parquet(rest)
    return run_rust(args)


def _sweep_parquet(rest: List[str]) -> int:
    """``popup sweep ... --parquet``: the Rust sweep writes ``summary.csv``; the summary is
    also written as ``summary.parquet`` (pyarrow), with the same columns and values."""
    args = [a for a in rest if a != "--parquet"]
    if not any(a in _HELP for a in args) and not _module_exists("pyarrow"):
        # checked before the sweep runs: no work is done for a summary that cannot be written
        print(
            f"{PROG}: error: --parquet needs pyarrow, which is not installed; install it (pip install pyarrow) "
            "or leave out --parquet (summary.csv is always written)",
            file=sys.stderr,
        )
        return 2
    code = run_rust(["sweep", *args])
    out = next((a.split("=", 1)[1] for a in args if a.startswith("--out=")), None)
    if out is None and "--out" in args and args.index("--out") + 1 < len(args):
        out = args[args.index("--out") + 1]
    csv = None if out is None else os.path.join(out, "summary.csv")
    if code in (0, 1) and csv is not None and os.path.isfile(csv):
        import pandas as pd

        pq = os.path.join(out or ".", "summary.parquet")
        pd.read_csv(csv).to_parquet(pq, index=False)
        print(f"{PROG}: summary also written as {pq}", file=sys.stderr)
    return code


def run_rust(args: Sequence[str]) -> int:
    """The Rust CLI on ``args`` (without the program name): its exit code. It writes to the
    process's file descriptors 1 and 2, so Python's buffers are flushed first; Ctrl-C
    stops it as it stops the Rust binary (the default SIGINT action, for the call)."""
    from . import _core

    _flush()
    if args and args[0] in SIGNAL_AWARE:
        # the run's own handlers finish the log on Ctrl-C, then Python's KeyboardInterrupt
        # (chained) arrives: the exit code is the run's
        code = 130
        try:
            code = int(_core.run_cli([PROG, *args]))
        except KeyboardInterrupt:
            pass
        return code
    with _default_sigint():
        return int(_core.run_cli([PROG, *args]))


def print_help(file: Optional[TextIO] = None) -> None:
    """The help of ``popup``: the Python and the Rust subcommands."""
    out = sys.stdout if file is None else file
    rust, raw = rust_commands()
    width = max(len(n) for n in [*PYTHON_COMMANDS, *(n for n, _ in rust)]) + 2
    lines = [
        "Simulation and model validation of inflatable robot arms",
        "",
        f"Usage: {PROG} <COMMAND> [ARGS]...",
        "",
        "Commands (Python):",
    ]
    for name, (module, summary) in PYTHON_COMMANDS.items():
        missing = "" if _module_exists(module) else " [not in this installation yet]"
        lines.append(f"  {name:<{width}}{summary}{missing}")
    lines += ["", "Commands (Rust engine, headless):"]
    if rust:
        lines += [f"  {name:<{width}}{summary}" for name, summary in rust]
    else:  # help text not in the expected clap layout: show it as it is
        lines += ["  " + ln for ln in raw.splitlines()]
    lines += [
        "",
        "Options:",
        "  -h, --help     Print help",
        "  -V, --version  Print version",
        "",
        f"`{PROG} <COMMAND> --help` shows the options of a command.",
    ]
    _flush()
    print("\n".join(lines), file=out)
    out.flush()


def rust_commands() -> Tuple[List[Tuple[str, str]], str]:
    """The Rust CLI's subcommands as ``(name, summary)`` pairs, read from its own
    ``--help`` (so new Rust subcommands show up without touching this file), and that
    help text. Clap's ``help`` subcommand is left out (``popup help`` is routed here)."""
    from . import _core

    code, text = _capture_fd1(lambda: _core.run_cli([PROG, "--help"]))
    cmds: List[Tuple[str, str]] = []
    in_commands = False
    for line in text.splitlines():
        if line.strip() == "Commands:":
            in_commands = True
            continue
        if in_commands:
            m = re.match(r"^  (\S+)\s+(.*)$", line)
            if m is None:
                if line.startswith("   "):  # a wrapped summary
                    continue
                break
            if m.group(1) != "help":
                cmds.append((m.group(1), m.group(2)))
    if code != 0:
        cmds = []
    return cmds, text


def _run_python(name: str, args: List[str]) -> int:
    module, _ = PYTHON_COMMANDS[name]
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name != module:  # the module exists but something it imports does not
            raise
        print(
            f"{PROG}: error: '{name}' is not available in this installation yet "
            f"(the Python module {module} is missing)",
            file=sys.stderr,
        )
        return 2
    cli_main: Optional[Callable[[List[str]], Optional[int]]] = getattr(mod, "cli_main", None)
    if cli_main is None:
        print(
            f"{PROG}: error: '{name}' is not available in this installation yet ({module} has no cli_main)",
            file=sys.stderr,
        )
        return 2
    try:
        code = cli_main(list(args))
    except SystemExit as e:  # argparse and friends exit; keep main() a function
        code = _exit_code(e.code)
    return 0 if code is None else int(code)


def _exit_code(code: object) -> int:
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)  # what sys.exit("message") does
    return 1


def _module_exists(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # ValueError: in sys.modules without a __spec__
        return False


def _flush() -> None:
    for f in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            f.flush()


@contextlib.contextmanager
def _default_sigint() -> Iterator[None]:
    """Default SIGINT action while Rust runs without the GIL: Python's handler would only
    set a flag that nobody checks until the run ends. Only in the main thread and only in
    place of Python's own handler (an ignored SIGINT stays ignored, as for the binary)."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _capture_fd1(fn: Callable[[], int]) -> Tuple[int, str]:
    """Run ``fn`` with file descriptor 1 redirected to a temporary file (Rust writes there,
    not to ``sys.stdout``); its return value and what it wrote."""
    _flush()
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(1)
        try:
            os.dup2(tmp.fileno(), 1)
            code = fn()
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        tmp.seek(0)
        return code, tmp.read().decode("utf-8", "replace")


if __name__ == "__main__":
    sys.exit(main())
