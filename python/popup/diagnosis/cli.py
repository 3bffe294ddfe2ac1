"""``popup diagnose RUN``: the command line, with its progress display on stderr."""

from __future__ import annotations

import contextlib
import json
import math
import signal
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterator, Optional, Sequence

from ..exceptions import InputError
from ..problem import ERROR_DEFINITION
from .loop import improve


class TerminalProgress:
    """Progress of :func:`improve` on a terminal (stderr, one line rewritten): round,
    effect, fits done and an ETA from the mean time per fit so far."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.t0 = time.perf_counter()
        self.fits = 0

    def __call__(self, info: Dict[str, Any]) -> None:
        self.fits += 1
        el = time.perf_counter() - self.t0
        left = max(int(info.get("total", 0)) - int(info.get("done", 0)), 0)
        eta = el / max(self.fits - 1, 1) * left if self.fits > 1 else math.nan
        eta_txt = f"ETA this round {eta:4.0f} s" if math.isfinite(eta) else "ETA …"
        line = f"popup diagnose: round {info.get('round', 1)}  {str(info.get('effect', '')):<32} {info.get('done', 0)}/{info.get('total', 0)} fits  {el:5.0f} s  {eta_txt}"
        self.stream.write("\r" + line[:118].ljust(118))
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\r" + " " * 118 + "\r")
        self.stream.flush()


@contextlib.contextmanager
def _interrupts(time_limit: Optional[float]) -> Iterator[None]:
    """SIGTERM, and SIGALRM after ``time_limit`` seconds, raise ``KeyboardInterrupt`` (with
    the reason) in the main thread while the loop runs, as Ctrl-C does: :func:`improve`
    then returns the rounds finished. Elsewhere (another thread, no SIGALRM) nothing is
    installed and a time limit is refused."""
    if threading.current_thread() is not threading.main_thread():
        if time_limit is not None:
            raise InputError("input --time-limit: only available in the main thread")
        yield
        return

    def stop(why: str) -> Callable[[int, Any], None]:
        def handler(signum: int, frame: Any) -> None:
            raise KeyboardInterrupt(why)

        return handler

    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, stop("SIGTERM received"))}
    if time_limit is not None:
        if not hasattr(signal, "setitimer"):
            signal.signal(signal.SIGTERM, old[signal.SIGTERM])
            raise InputError("input --time-limit: not available on this platform (no SIGALRM)")
        old[signal.SIGALRM] = signal.signal(signal.SIGALRM, stop(f"the time limit of {time_limit:g} s was reached"))
        signal.setitimer(signal.ITIMER_REAL, time_limit)
    try:
        yield
    finally:
        if time_limit is not None:
            signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, h in old.items():
            signal.signal(sig, h)


def cli_main(argv: Sequence[str]) -> int:
    """``popup diagnose RUN [--json] [--report out.html] ...``: load the run, compare,
    rank every effect, add the significant ones in turn (refitting), print the suspects
    and the error fall (or one JSON object with ``--json``). Exit 0 when complete, 1 when a
    round failed or was interrupted (Ctrl-C, SIGTERM or ``--time-limit``: what finished is
    still printed and reported, with the error), 2 on bad input (the message names what
    was wrong), 130 when interrupted before the first round began."""
    import argparse

    from ..exceptions import PopupError
    from ..io import read_run

    ap = argparse.ArgumentParser(prog="popup diagnose", description="Rank the library's effects by how much of the model's systematic error each explains, then add them in turn.")
    ap.add_argument("run", help="measured-run folder (experiment.toml + measurements.csv/parquet) or MCAP log")
    ap.add_argument("--json", action="store_true", help="print one JSON object (run, nominal_error, error_definition, noise, suspects, history, conclusion, ...)")
    ap.add_argument("--report", metavar="HTML", help="write the self-contained HTML report here")
    ap.add_argument("--max-rounds", type=int, default=4, help="most effects to add (default 4)")
    ap.add_argument("--effects", help="comma-separated effects to try (default: the whole library)")
    ap.add_argument("--channels", help="comma-separated channels to compare (default: every comparable one)")
    ap.add_argument("--threads", type=int, default=0, help="cores to use: candidates fitted at once, each with a share of them as rollout threads; the result does not depend on it (0 = all cores)")
    ap.add_argument("--rank-at-floor", action="store_true",
                    help="fit and rank every effect even when the model is at its floor (noise and encoder); by default they are not tried")
    off = ap.add_mutually_exclusive_group()
    off.add_argument("--offsets", dest="offsets", action="store_const", const=True, default=None,
                     help="fit a constant offset per channel with every model (sensor biases, calibration offsets the run still has); "
                          "default: only when what the loop leaves is mostly constant offsets (the run is then diagnosed again)")
    off.add_argument("--no-offsets", dest="offsets", action="store_const", const=False,
                     help="never fit constant offsets (they stay in the error; the conclusion names large ones)")
    ap.add_argument("--no-progress", action="store_true", help="no progress line on stderr (it is off anyway with --json or when stderr is not a terminal)")
    ap.add_argument("--time-limit", type=float, metavar="SECONDS",
                    help="stop after this many seconds and print the rounds finished (as on Ctrl-C or SIGTERM), exit 1")
    a = ap.parse_args(list(argv))
    if a.time_limit is not None and not (math.isfinite(a.time_limit) and a.time_limit > 0):
        print(f"popup diagnose: error: input --time-limit: {a.time_limit} must be a positive number of seconds", file=sys.stderr)
        return 2
    show = not a.json and not a.no_progress and sys.stderr.isatty()
    bar = TerminalProgress() if show else None
    try:
        run = read_run(a.run)
        model = run.model()
        effects = [e.strip() for e in a.effects.split(",")] if a.effects else None
        channels = [c.strip() for c in a.channels.split(",")] if a.channels else None
        with _interrupts(a.time_limit):
            h = improve(model, run, max_rounds=a.max_rounds, effects=effects, channels=channels, threads=a.threads, progress=bar,
                        rank_at_floor=a.rank_at_floor, stop_on_interrupt=True, offsets=a.offsets)
    except (PopupError, FileNotFoundError, NotADirectoryError) as e:
        if bar is not None:
            bar.close()
        print(f"popup diagnose: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # in the set-up, before any round: nothing to print
        if bar is not None:
            bar.close()
        print(f"popup diagnose: interrupted before the first round: {e or 'KeyboardInterrupt'}", file=sys.stderr)
        return 130
    if bar is not None:
        bar.close()
    h.run = a.run
    for d in h.diagnoses:
        d.run = a.run
    rc = 0 if h.complete else 1
    if a.report:
        from ..report import write_html

        try:
            write_html(h, a.report, title=f"popup diagnose {a.run}")
        except Exception as e:  # noqa: BLE001 - the numbers still go out
            print(f"popup diagnose: error: could not write the report {a.report}: {type(e).__name__}: {e}", file=sys.stderr)
            rc = 1
    if a.json:
        print(json.dumps(h.to_dict(), allow_nan=False))
        return rc
    print(f"run: {a.run}")
    print(f"error: {ERROR_DEFINITION}")
    print(f"nominal error: {h.steps[0].error:.4g} noise units")
    floor = h.at_floor
    print("channels (noise σ, nominal → final noise multiple):")
    for c, v in h.steps[0].channel_error.items():
        print(f"  {c:<9} σ = {h.noise.get(c, math.nan):<10.3g} {v:8.3g}× → {h.steps[-1].channel_error.get(c, math.nan):.3g}×{'  (signal at the noise floor)' if c in floor else ''}")
    if h.diagnoses:
        d0 = h.diagnoses[0]
        print()
        if h.noise_initial and h.noise_initial != h.noise:
            print(f"first round (in the floors first estimated, nominal error {d0.nominal_error:.4g} in them; popup.History.noise_initial):")
        print(f"{'rank':>4}  {'effect':<22}{'sig':<5}{'score':>10}{'error after':>13}{'explained':>10}  parameters")
        for i, s in enumerate(d0.suspects, 1):
            score = f"{s.score:.1f}" if math.isfinite(s.score) else "n/a"
            params = s.params_text() if s.tested else s.message
            after = f"{s.error_after:.4g}" if s.tested else "not tested"
            print(f"{i:>4}  {s.effect:<22}{'yes' if s.significant else 'no':<5}{score:>10}{after:>13}{100 * s.explained:>9.0f}%  {params}")
    print()
    print("error history (systematic error, noise units):")
    for st in h.steps:
        print(f"  {' + '.join(st.effects) or 'nominal':<40} {st.error:.4g}")
    print()
    print(h.conclusion)
    if h.error:
        print(f"popup diagnose: incomplete: {h.error}", file=sys.stderr)
    if a.report:
        print(f"report: {a.report}")
    return rc
