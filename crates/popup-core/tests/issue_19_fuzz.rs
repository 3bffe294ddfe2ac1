//! Issue 19: property tests of the parsers and bounds on arbitrary and mutated input:
//! never a panic, always a result or a named error, quickly. A short run in CI (256 cases
//! per target); `PROPTEST_CASES=20000 cargo test --release --test issue_19_fuzz` (or
//! `scripts/fuzz.sh`) for a long one.

use popup_core::limits::{check_steps, MAX_STEPS};
use popup_core::scenario::Scenario;
use popup_core::spec::ArmSpec;
use proptest::prelude::*;
use std::path::Path;

const SCENARIO: &str = include_str!("../../../examples/scenarios/pick_and_place.toml");

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(256)
}

/// A text with one edit: a byte range replaced by an arbitrary string.
fn mutate(base: &str, at: usize, cut: usize, insert: &str) -> String {
    let b = base.as_bytes();
    let at = at % (b.len() + 1);
    let end = (at + cut).min(b.len());
    let mut out = b[..at].to_vec();
    out.extend_from_slice(insert.as_bytes());
    out.extend_from_slice(&b[end..]);
    String::from_utf8_lossy(&out).into_owned()
}

/// Values that break parsers and loops.
fn nasty() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("1e300".to_string()),
        Just("-1e300".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-0.0".to_string()),
        Just("0".to_string()),
        Just("18446744073709551616".to_string()),
        Just("[".to_string()),
        Just("\"\"".to_string()),
        Just("[[phases]]\n".to_string()),
        "[ -~\n]{0,24}",
    ]
}

/// Every problem names a file and a message: the parser's contract.
fn problems_are_named(r: Result<Scenario, Vec<popup_core::scenario::Problem>>) -> Result<(), TestCaseError> {
    if let Err(ps) = r {
        prop_assert!(!ps.is_empty());
        for p in ps {
            prop_assert!(!p.message.is_empty() && !p.file.is_empty(), "{p:?}");
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn scenario_parser_never_panics_on_arbitrary_text(text in "[ -~\n]{0,400}") {
        problems_are_named(Scenario::parse(&text, "fuzz.toml", Path::new(".")))?;
    }

    #[test]
    fn scenario_parser_never_panics_on_a_mutated_scenario(at in 0usize..4000, cut in 0usize..40, insert in nasty()) {
        let text = mutate(SCENARIO, at, cut, &insert);
        problems_are_named(Scenario::parse(&text, "fuzz.toml", Path::new(".")))?;
    }

    #[test]
    fn scenario_values_are_refused_or_bounded(key in prop_oneof![Just("duration_s"), Just("dt"), Just("sample_rate_hz"), Just("payload_kg")], v in nasty()) {
        let text = format!("{SCENARIO}\n").replacen(&format!("\n{key} ="), &format!("\n{key} = {v}\n_old_{key} ="), 1);
        if let Ok(sc) = Scenario::parse(&text, "fuzz.toml", Path::new(".")) {
            // a scenario that parses has a bounded run: its step count passes the check
            let n = check_steps("duration", sc.closed.duration, sc.options.dt);
            prop_assert!(n.map_or(true, |n| n as f64 <= MAX_STEPS));
        }
    }

    #[test]
    fn arm_parser_never_panics(at in 0usize..6000, cut in 0usize..40, insert in nasty()) {
        let base = ArmSpec::popup_lab().to_toml();
        let text = mutate(&base, at, cut, &insert);
        if let Err(e) = ArmSpec::from_toml(&text, "fuzz-arm.toml") {
            prop_assert!(!e.to_string().is_empty());
        }
    }

    #[test]
    fn arm_parser_never_panics_on_arbitrary_text(text in "[ -~\n]{0,300}") {
        let _ = ArmSpec::from_toml(&text, "fuzz-arm.toml");
    }

    #[test]
    fn step_bound_never_panics_and_holds(d in proptest::num::f64::ANY, dt in proptest::num::f64::ANY) {
        if let Ok(n) = check_steps("duration", d, dt) {
            prop_assert!(d.is_finite() && dt > 0.0 && n as f64 <= MAX_STEPS);
        }
    }
}
