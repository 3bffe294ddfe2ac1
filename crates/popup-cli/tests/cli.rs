//! Exit codes of the CLI, through the library (`run_from_args`, what `popup._core.run_cli`
//! calls) and through the `popup` binary: both must agree, and the library must return
//! instead of exiting the process (a test that reaches its asserts proves that).

use popup_cli::run_from_args;
use std::process::Command;

fn bin(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_popup")).args(args).output().expect("run popup binary")
}

#[test]
fn library_returns_exit_codes() {
    assert_eq!(run_from_args(["popup", "info"]), 0);
    assert_eq!(run_from_args(["popup", "--help"]), 0);
    assert_eq!(run_from_args(["popup", "--version"]), 0);
    assert_eq!(run_from_args(["popup", "statics", "--q", "0,0.6,-0.3"]), 0);
    // usage errors (clap) and failed commands both give 2
    assert_eq!(run_from_args(["popup"]), 2);
    assert_eq!(run_from_args(["popup", "no-such-command"]), 2);
    assert_eq!(run_from_args(["popup", "statics", "--q", "1,2"]), 2);
    assert_eq!(run_from_args(["popup", "arm", "no-such-arm"]), 2);
}

#[test]
fn binary_matches_library() {
    let info = bin(&["info"]);
    assert_eq!(info.status.code(), Some(0));
    let out = String::from_utf8_lossy(&info.stdout);
    assert!(out.starts_with(&format!("popup {}\n", popup_core::VERSION)), "{out}");
    assert!(out.contains("built-in arms: popup-lab"), "{out}");

    let bad = bin(&["statics", "--q", "1,2"]);
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("popup: error:") && err.contains("--q"), "{err}");

    let unknown = bin(&["no-such-command"]);
    assert_eq!(unknown.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("no-such-command"));

    let help = bin(&["--help"]);
    assert_eq!(help.status.code(), Some(0));
    let h = String::from_utf8_lossy(&help.stdout);
    for cmd in ["info", "arm", "statics", "hold"] {
        assert!(h.contains(cmd), "{cmd} missing from --help:\n{h}");
    }
}
