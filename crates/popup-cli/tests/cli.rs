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

fn scenario(dir: &std::path::Path, body: &str) -> std::path::PathBuf {
    let p = dir.join("s.toml");
    std::fs::write(&p, body).unwrap();
    p
}

const HOLD: &str = "format = \"popup-scenario/1\"\nq0 = [0.0, 0.6, -0.4]\nduration_s = 60.0\ndt = 5e-4\nsample_rate_hz = 100.0\n[log]\nflush_every_s = 0.25\n[controller]\nrate_hz = 2000.0\n";

/// The binary finishes the file on SIGINT (exit 130) and the finished file has its
/// summary: the footer's summary-start offset is non-zero and the file ends in the magic.
#[test]
fn binary_sigint_finishes_the_log() {
    let dir = std::env::temp_dir().join(format!("popup-cli-sigint-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sc = scenario(&dir, HOLD);
    let out = dir.join("r.mcap");
    let mut child = Command::new(env!("CARGO_BIN_EXE_popup"))
        .args(["run", sc.to_str().unwrap(), "--out", out.to_str().unwrap(), "--progress", "lines"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    let mut flushed = 0;
    while flushed < 2 {
        line.clear();
        assert!(std::io::BufRead::read_line(&mut err, &mut line).unwrap() > 0, "run ended early");
        flushed += usize::from(line.contains("log flushed"));
    }
    let st = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(st.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    let bytes = std::fs::read(&out).unwrap();
    assert_eq!(&bytes[bytes.len() - 8..], b"\x89MCAP0\r\n");
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert!(summary.stats.unwrap().message_count > 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn binary_check_lists_problems_and_run_refuses_bad_scenarios() {
    let dir = std::env::temp_dir().join(format!("popup-cli-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sc = scenario(&dir, "format = \"popup-scenario/1\"\nduration_s = -1.0\npayload_kg = -2.0\n");
    let o = bin(&["check", sc.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(":2: duration_s:") && err.contains(":3: payload_kg:"), "{err}");
    let out = dir.join("r.mcap");
    let o = bin(&["run", sc.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!out.exists(), "nothing is created for an invalid scenario");
    let good = scenario(&dir, HOLD);
    let o = bin(&["check", good.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let o = bin(&["run", good.to_str().unwrap(), "--out", out.to_str().unwrap(), "--duration", "0.5"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(mcap::Summary::read(&std::fs::read(&out).unwrap()).unwrap().is_some());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Packaged arm files are taken by name wherever an arm is named, as `popup.Model(name)`
/// does (one resolution, `ArmSpec::resolve`): `--arm`, `popup arm NAME` and the `arm` key
/// of a scenario (`check`, `run`); an unknown name is refused with the known names.
#[test]
fn packaged_arms_by_name() {
    let o = bin(&["arm", "popup-lab-thesis"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("name = \"popup-lab-thesis\""), "{text}");
    assert_eq!(popup_core::spec::ArmSpec::from_toml(&text, "printed").unwrap(), popup_core::spec::ArmSpec::builtin("popup-lab-thesis").unwrap());
    let o = bin(&["statics", "--arm", "popup-lab-thesis", "--q", "0,1.5707963,-1.5707963"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("arm popup-lab-thesis payload 2 kg"));
    let o = bin(&["statics", "--arm", "no-such-arm"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    for name in popup_core::spec::ArmSpec::BUILTIN {
        assert!(err.contains(name), "{name} missing from: {err}");
    }
    let dir = std::env::temp_dir().join(format!("popup-cli-packaged-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sc = scenario(&dir, &format!("arm = \"popup-lab-thesis\"\n{HOLD}"));
    let o = bin(&["check", sc.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("arm popup-lab-thesis"));
    let out = dir.join("r.mcap");
    let o = bin(&["run", sc.to_str().unwrap(), "--out", out.to_str().unwrap(), "--duration", "0.2"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let bad = scenario(&dir, &format!("arm = \"no-such-arm\"\n{HOLD}"));
    let o = bin(&["check", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("arm") && err.contains("popup-lab-thesis"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
