"""Issue 19: property tests (hypothesis) of the measured-run readers and the replay API on
generated bad input. Property: every input ends, within a bounded time, in a valid run
or a :class:`popup.PopupError` whose message names the file (or the argument); nothing
else escapes. A short run here (CI); ``-m slow`` for a long one, or
``scripts/fuzz.sh`` which also prints the count of inputs tried."""

import contextlib
import functools
import math
import os
import signal
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import popup
from popup import io as pio

#: Seconds one case may take before it counts as a hang.
CASE_LIMIT_S = 20.0

EXP = 'format = "popup-run/1"\narm = "popup-lab"\npayload_kg = 2.0\npressure_pa = [30000.0, 30000.0]\nreplay = "encoder"\n'

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
LONG = settings(max_examples=int(os.environ.get("POPUP_FUZZ_EXAMPLES", "2000")), deadline=None, suppress_health_check=list(HealthCheck))


@contextlib.contextmanager
def bounded(seconds: float = CASE_LIMIT_S):
    """Fail the case (TimeoutError) if it runs longer than ``seconds``: a hang is a bug."""
    if os.name != "posix":
        yield
        return

    def boom(*_):
        raise TimeoutError(f"case ran longer than {seconds} s")

    old = signal.signal(signal.SIGALRM, boom)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def outcome(call, where: str):
    """Run ``call`` bounded; it must return or raise a PopupError naming ``where``."""
    with bounded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)
        try:
            return call()
        except popup.PopupError as e:
            msg = str(e)
            assert msg and where in msg, msg
            return e


# --------------------------------------------------------------------------- CSV runs
NASTY = st.sampled_from(["", "nan", "inf", "-inf", "1e300", "-1e300", "1e9", "0", "-0", "x", "1,5", '"', "1e", "True", " 1", "1e-300", "55"])
NUM = st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr)
CELL = st.one_of(NASTY, NUM, st.floats(-3.0, 3.0).map(repr))
COLUMNS = st.lists(st.sampled_from([*pio.MEASURED_COLUMNS, "T", "q1 ", "bogus", ""]), min_size=1, max_size=6)


@st.composite
def csv_texts(draw):
    cols = draw(COLUMNS)
    if draw(st.booleans()):
        cols = ["t", "q1", "q2", "q3", *cols]
    n = draw(st.integers(0, 12))
    t0 = draw(st.floats(-1.0, 1.0))
    rows = []
    for i in range(n):
        row = []
        for c in cols:
            if c == "t" and draw(st.integers(0, 4)) > 0:
                row.append(repr(t0 + 0.002 * i))  # mostly a plausible clock
            else:
                row.append(draw(CELL))
        rows.append(",".join(row))
    text = "\n".join([",".join(cols), *rows]) + "\n"
    if draw(st.booleans()):
        text = text.replace("\n", "\r\n")
    if draw(st.integers(0, 3)) == 0:
        text = text[: draw(st.integers(0, len(text)))]  # cut anywhere
    return text


def read_csv_run(tmp: Path, text: str):
    (tmp / "experiment.toml").write_text(EXP)
    (tmp / "measurements.csv").write_text(text)
    return outcome(lambda: pio.read_run(tmp), str(tmp))


@FAST
@given(text=csv_texts())
def test_read_run_on_generated_csv_is_a_run_or_a_named_error(text):
    with tempfile.TemporaryDirectory() as d:
        r = read_csv_run(Path(d), text)
    if isinstance(r, pio.MeasuredRun):
        t = r.time
        assert t.size >= 1 and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)


@pytest.mark.slow
@LONG
@given(text=csv_texts())
def test_read_run_on_generated_csv_long(text):
    with tempfile.TemporaryDirectory() as d:
        read_csv_run(Path(d), text)


# --------------------------------------------------------------------------- MCAP runs
@functools.lru_cache(maxsize=1)
def mcap_bytes() -> bytes:
    """A real log of a short replay (made once)."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run.mcap"
        t = np.arange(0.0, 0.3, 0.002)
        q = np.zeros((t.size, 3))
        q[:, 1] = 0.3 * t
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", popup.PopupWarning)
            popup.Model().replay(t, q, log=out)
        return out.read_bytes()


#: (cut at this fraction of the file or None, [(fraction, byte)]): truncation and byte flips.
DAMAGE = st.tuples(
    st.one_of(st.none(), st.floats(0.0, 1.0)),
    st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True), st.integers(0, 255)), max_size=4),
)


def read_damaged(cut, flips):
    data = mcap_bytes()
    b = bytearray(data)
    for frac, v in flips:
        b[int(frac * len(b))] = v
    if cut is not None:
        b = b[: int(cut * len(data))]
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "run.mcap"
        p.write_bytes(bytes(b))
        return outcome(lambda: pio.read_run(p), str(p))


@FAST
@given(dmg=DAMAGE)
def test_read_run_on_damaged_mcap_is_a_run_or_a_named_error(dmg):
    read_damaged(*dmg)


@pytest.mark.slow
@LONG
@given(dmg=DAMAGE)
def test_read_run_on_damaged_mcap_long(dmg):
    read_damaged(*dmg)


# --------------------------------------------------------------------------- the replay API
FLOATS = st.one_of(st.floats(-1.0, 1.0), st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, 55.0]))


@st.composite
def replay_args(draw):
    n = draw(st.integers(0, 6))
    # time stamps within 1 s (or absurd ones): a plausible replay is short, so cases stay fast
    t = sorted(draw(st.lists(st.one_of(st.floats(0.0, 1.0), st.sampled_from([math.nan, 1e300, 1e9])), min_size=n, max_size=n)))
    q = draw(st.lists(st.lists(FLOATS, min_size=3, max_size=3), min_size=n, max_size=n))
    shape_bug = draw(st.integers(0, 5)) == 0
    if shape_bug and q:
        q = [row[:2] for row in q]
    return t, q


@FAST
@given(args=replay_args())
def test_replay_on_generated_arguments_is_a_result_or_a_named_error(model, args):
    t, q = args
    r = outcome(lambda: model.replay(t, q, sample_rate=100), "input")
    if isinstance(r, popup.PopupError):
        assert isinstance(r, (ValueError, RuntimeError)), type(r)

