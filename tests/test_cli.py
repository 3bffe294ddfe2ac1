"""The one ``popup`` command (``popup.cli``): Python subcommands and the Rust CLI's,
through ``python -m popup`` and the installed entry point."""

import importlib
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
import types

import pytest

import popup
from popup import cli

RUST_COMMANDS = ["info", "run", "sweep", "check", "arm", "statics", "hold"]


def _script():
    """The ``popup`` console script of this interpreter's environment, else the one on PATH."""
    return shutil.which("popup", path=sysconfig.get_path("scripts")) or shutil.which("popup")


COMMANDS = [pytest.param([sys.executable, "-m", "popup"], id="python-m-popup")]
if _script():
    COMMANDS.append(pytest.param([_script()], id="popup-script"))


@pytest.fixture(params=COMMANDS)
def popup_cmd(request):
    return request.param


def run(cmd, *args, timeout=120):
    return subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=timeout)


def test_info(popup_cmd):
    r = run(popup_cmd, "info")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == f"popup {popup.__version__}", r.stdout
    assert "built-in arms:" in r.stdout and "popup-lab" in r.stdout


def test_version_goes_to_rust(popup_cmd):
    r = run(popup_cmd, "--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"popup {popup.__version__}"


def test_statics(popup_cmd):
    r = run(popup_cmd, "statics", "--q", "0,0.6,-0.3", "--payload-kg", "1.5")
    assert r.returncode == 0, r.stderr
    assert "payload 1.5 kg" in r.stdout and "holding torques" in r.stdout


def test_unknown_subcommand(popup_cmd):
    r = run(popup_cmd, "no-such-command")
    assert r.returncode == 2
    assert "unrecognized subcommand 'no-such-command'" in r.stderr
    assert r.stdout == ""


def test_rust_bad_input_exit_code(popup_cmd):
    # a failed Rust command: the CLI's own message and exit code 2
    r = run(popup_cmd, "statics", "--q", "1,2")
    assert r.returncode == 2
    assert "popup: error:" in r.stderr and "--q" in r.stderr and "got 2" in r.stderr
    r = run(popup_cmd, "arm", "no-such-arm")
    assert r.returncode == 2
    assert "popup: error:" in r.stderr and "no-such-arm" in r.stderr


def test_help_lists_python_and_rust(popup_cmd):
    for flag in ("--help", "-h", "help"):
        r = run(popup_cmd, flag)
        assert r.returncode == 0, r.stderr
        listed = [ln.split()[0] for ln in r.stdout.splitlines() if ln.startswith("  ") and not ln.startswith("  -")]
        assert "diagnose" in listed, r.stdout
        for name in RUST_COMMANDS:
            assert name in listed, (name, r.stdout)
        assert "help" not in listed  # clap's own `help` is routed to this help


def test_no_args_is_a_usage_error_with_help(popup_cmd):
    r = run(popup_cmd)
    assert r.returncode == 2
    assert r.stdout == ""
    assert "diagnose" in r.stderr and "statics" in r.stderr


def test_subcommand_help_goes_to_rust(popup_cmd):
    r = run(popup_cmd, "statics", "--help")
    assert r.returncode == 0, r.stderr
    assert "Usage: popup statics" in r.stdout and "--payload-kg" in r.stdout
    r = run(popup_cmd, "help", "hold")
    assert r.returncode == 0, r.stderr
    assert "Usage: popup hold" in r.stdout


def test_diagnose(popup_cmd):
    # `popup diagnose` is popup.diagnosis.cli_main; before that exists, a clear error
    if importlib.util.find_spec("popup.diagnosis") is None or not hasattr(
        importlib.import_module("popup.diagnosis"), "cli_main"
    ):
        r = run(popup_cmd, "diagnose")
        assert r.returncode == 2
        assert "'diagnose' is not available in this installation yet" in r.stderr, r.stderr
        assert "popup.diagnosis" in r.stderr
    else:
        r = run(popup_cmd, "diagnose", "--help")
        assert r.returncode == 0, r.stderr
        assert "usage: popup diagnose" in r.stdout, r.stdout
        # argparse's usage error (SystemExit(2)) comes through as exit code 2
        r = run(popup_cmd, "diagnose", "--no-such-option")
        assert r.returncode == 2, r.stderr


def test_script_is_the_python_entry_point():
    script = _script()
    if script is None:
        pytest.skip("no `popup` script installed (pip install -e . installs one)")
    r = run([script, "--help"])
    assert "diagnose" in r.stdout, f"{script} is not popup.cli:main (a Rust-only binary?)"


# --- in-process: routing and exit codes of popup.cli.main ---------------------------------


def test_main_returns_rust_exit_codes(capfd):
    assert cli.main(["info"]) == 0
    assert f"popup {popup.__version__}" in capfd.readouterr().out
    assert cli.main(["statics", "--q", "1,2"]) == 2
    assert "popup: error:" in capfd.readouterr().err
    assert cli.main(["no-such-command"]) == 2


def test_rust_commands_read_from_rust_help():
    names = [n for n, _ in cli.rust_commands()[0]]
    assert names[: len(RUST_COMMANDS)] == RUST_COMMANDS
    assert "help" not in names


@pytest.fixture
def fake_command(monkeypatch):
    """A Python subcommand `fake` backed by a module made here."""
    mod = types.ModuleType("popup._fake_cmd")
    monkeypatch.setitem(sys.modules, "popup._fake_cmd", mod)
    monkeypatch.setitem(cli.PYTHON_COMMANDS, "fake", ("popup._fake_cmd", "a test command"))
    return mod


def test_python_command_routing(fake_command, capsys):
    seen = []

    def cli_main(args):
        seen.append(args)
        return 3

    fake_command.cli_main = cli_main
    assert cli.main(["fake", "--x", "1"]) == 3
    assert seen == [["--x", "1"]]
    assert cli.main(["help", "fake"]) == 3
    assert seen[-1] == ["--help"]
    cli.main(["--help"])
    assert "fake" in capsys.readouterr().out


def test_python_command_system_exit(fake_command, capsys):
    def cli_main(args):
        raise SystemExit(int(args[0]) if args[0].isdigit() else args[0])

    fake_command.cli_main = cli_main
    assert cli.main(["fake", "0"]) == 0
    assert cli.main(["fake", "4"]) == 4
    assert cli.main(["fake", "bad things"]) == 1
    assert "bad things" in capsys.readouterr().err


def test_python_command_without_cli_main(fake_command, capsys):
    assert cli.main(["fake"]) == 2
    assert "'fake' is not available in this installation yet" in capsys.readouterr().err


def test_python_command_module_missing(monkeypatch, capsys):
    monkeypatch.setitem(cli.PYTHON_COMMANDS, "fake", ("popup._no_such_module_for_test", "x"))
    assert cli.main(["fake"]) == 2
    err = capsys.readouterr().err
    assert "'fake' is not available in this installation yet" in err and "popup._no_such_module_for_test" in err
    cli.main(["--help"])
    assert "[not in this installation yet]" in capsys.readouterr().out


def test_missing_dependency_is_not_hidden(monkeypatch):
    # a module that exists but fails to import something else must not read "not available"
    monkeypatch.setitem(cli.PYTHON_COMMANDS, "fake", ("popup._no_such_module_for_test", "x"))
    monkeypatch.setattr(
        cli.importlib, "import_module", lambda name: (_ for _ in ()).throw(ModuleNotFoundError("no dep", name="somedep"))
    )
    with pytest.raises(ModuleNotFoundError, match="no dep"):
        cli.main(["fake"])


def _default_sigint() -> None:
    """In the child: SIGINT back to its default (a shell's background job starts with it
    ignored, and Python then installs no KeyboardInterrupt handler)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_ctrl_c_stops_a_rust_run():
    # without the GIL, Python's SIGINT handler would never run: the run must die like the binary
    p = subprocess.Popen(
        [sys.executable, "-m", "popup", "hold", "--duration", "1e6", "--sample-rate", "0.001", "--out", os.devnull],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )
    try:
        time.sleep(3.0)
        assert p.poll() is None, p.communicate()
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    if p.returncode == 1 and "KeyboardInterrupt" in err:
        pytest.skip("SIGINT arrived before the Rust run started (slow start-up)")
    assert p.returncode == -signal.SIGINT, err


def test_sweep_parquet_without_pyarrow_is_a_clear_error(tmp_path, monkeypatch, capsys):
    # issue 19: not a traceback; refused before any run
    real = cli._module_exists
    monkeypatch.setattr(cli, "_module_exists", lambda m: False if m == "pyarrow" else real(m))
    ran = []
    monkeypatch.setattr(cli, "run_rust", lambda args: ran.append(args) or 0)
    code = cli.main(["sweep", "sc.toml", "--param", "payload_kg=1", "--out", str(tmp_path), "--parquet"])
    err = capsys.readouterr().err
    assert code == 2 and ran == []
    assert "--parquet needs pyarrow" in err and "pip install pyarrow" in err and "Traceback" not in err, err


def test_packaged_arms_by_name(popup_cmd, tmp_path):
    """Packaged arm files resolve by name in every command as in ``popup.Model(name)``: one
    list (``popup.arm_names()``, the core's), one resolution. The Rust commands take it as
    ``--arm`` (``statics``), ``popup arm NAME`` and a scenario's ``arm`` key (``check``,
    ``run``); ``popup diagnose`` reads it from a measured run's ``experiment.toml``. The
    CLI's holding torques equal the Python model's (the same arm), and an unknown name is
    refused naming every known one."""
    import numpy as np

    names = popup.arm_names()
    assert names[0] == "popup-lab" and "popup-lab-thesis" in names
    q = (0.0, 1.5707963, -1.5707963)
    r = run(popup_cmd, "statics", "--arm", "popup-lab-thesis", "--q", ",".join(map(str, q)))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("arm popup-lab-thesis payload 2 kg"), r.stdout
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("holding torques"))
    tau_cli = np.array([float(x) for x in line.split(":", 1)[1].strip(" []").split(",")])
    m = popup.Model("popup-lab-thesis")
    np.testing.assert_allclose(tau_cli, m.holding_torque(q), rtol=1e-9, atol=1e-9)
    assert not np.allclose(tau_cli, popup.Model("popup-lab").holding_torque(q), rtol=1e-3)
    r = run(popup_cmd, "arm", "popup-lab-thesis")
    assert r.returncode == 0, r.stderr
    assert popup.Arm.from_toml(r.stdout).to_toml() == m.arm.to_toml()

    for args in (("statics", "--arm", "no-such-arm"), ("arm", "no-such-arm")):
        r = run(popup_cmd, *args)
        assert r.returncode == 2
        assert "no-such-arm" in r.stderr and all(n in r.stderr for n in names), r.stderr
    with pytest.raises(popup.UnknownArmError) as e:
        popup.Model("no-such-arm")
    assert all(n in str(e.value) for n in names)

    body = 'format = "popup-scenario/1"\narm = "{}"\nq0 = [0.0, 0.6, -0.4]\nduration_s = 0.1\ndt = 5e-4\nsample_rate_hz = 100.0\n[controller]\nrate_hz = 2000.0\n'
    sc = tmp_path / "s.toml"
    sc.write_text(body.format("popup-lab-thesis"))
    r = run(popup_cmd, "check", str(sc))
    assert r.returncode == 0, r.stderr
    assert "arm popup-lab-thesis" in r.stdout, r.stdout
    r = run(popup_cmd, "run", str(sc), "--out", str(tmp_path / "r.mcap"))
    assert r.returncode == 0, r.stderr
    sc.write_text(body.format("no-such-arm"))
    r = run(popup_cmd, "check", str(sc))
    assert r.returncode == 2 and all(n in r.stderr for n in names), r.stderr

    # a measured run of the packaged arm names it in experiment.toml; diagnose reads it
    q0 = (0.0, 0.6, -0.4)
    res = m.simulate(m.holding_torque(q0), duration=0.2, initial_q=m.rest_state(q0), sample_rate=100.0)
    df = popup.io.from_sim(res)
    assert df.attrs["experiment"]["arm"] == "popup-lab-thesis"
    popup.io.write_run(tmp_path / "run", df.attrs["experiment"], df)
    assert popup.io.read_run(tmp_path / "run").model().arm.to_toml() == m.arm.to_toml()
