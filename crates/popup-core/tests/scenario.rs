//! Scenario files: parsing, every problem reported with its line and key, key edits for
//! sweeps, sweep value specs, the experiment.toml of a run, the bundled examples.

use popup_core::control::machine::{Command, FaultAction};
use popup_core::control::run_closed_loop;
use popup_core::control::Status;
use popup_core::model::Integrator;
use popup_core::scenario::{parse_values, set_key, Compression, Problem, Scenario, SCENARIO_FORMAT, TOPICS};
use std::path::{Path, PathBuf};

fn parse(text: &str) -> Result<Scenario, Vec<Problem>> {
    Scenario::parse(text, "s.toml", Path::new("."))
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/scenarios")
}

const FULL: &str = r#"format = "popup-scenario/1"
description = "full"
arm = "popup-lab"
payload_kg = 1.5
pressure_pa = [40000.0, 50000.0]
gravity = false
q0 = [0.1, 0.5, -0.3]
duration_s = 2.5
dt = 2e-4
integrator = "semi_implicit"
sample_rate_hz = 250.0
seed = 42
payload_radius_m = 0.07

[effects.joint_friction]
tau_c = [0.5, 0.5, 0.5]
[effects.sensor_delay]
imu = 0.002

[noise]
encoder_rad = 0.001
imu_m_s2 = 0.05
torque_nm = 0.1
mocap_m = 0.002

[log]
viz_rate_hz = 25.0
flush_every_s = 0.5
compression = "lz4"
chunk_size_bytes = 65536
topics = ["joints", "events"]

[controller]
rate_hz = 5000.0
damping = [true, true, false]
[controller.gains]
vel_kp = 1000.0
[controller.motor]
tau_max = 80.0

[faults]
wrinkle = "continue"

[[obstacles]]
name = "table"
plane = { point = [0.0, 0.0, -0.4], normal = [0.0, 0.0, 1.0] }

[[phases]]
kind = "moving"
move_to = { q = [0.2, 0.6, -0.4], duration = 1.0 }
[[phases]]
kind = "grasping"
payload_kg = 2.0
"#;

#[test]
fn a_full_scenario_parses_to_what_it_says() {
    let s = parse(FULL).unwrap_or_else(|p| panic!("{p:#?}"));
    assert_eq!(s.description, "full");
    assert_eq!(s.arm_name, "popup-lab");
    assert_eq!(s.arm.name, "popup-lab");
    assert!(s.arm_file.is_none());
    assert_eq!(s.text, FULL);
    assert_eq!(s.source, "s.toml");
    assert_eq!(s.options.dt, 2e-4);
    assert_eq!(s.options.integrator, Integrator::SemiImplicit);
    assert!(s.options.disable.gravity && s.options.gravity.is_none());
    assert_eq!(s.params.payload_kg, 1.5);
    assert_eq!(s.params.pressure_pa, [40e3, 50e3]);
    assert_eq!(s.params.effects.joint_friction.tau_c, [0.5; 3]);
    assert_eq!(s.params.effects.sensor_delay.imu, 0.002);
    assert_eq!(s.arm.effects, s.params.effects);
    let c = &s.closed;
    assert_eq!(c.q0, [0.1, 0.5, -0.3]);
    assert_eq!(c.duration, 2.5);
    assert_eq!(c.sample_period, 1.0 / 250.0);
    assert!(c.check_step && c.initial.is_none());
    assert_eq!(c.payload_radius, 0.07);
    assert_eq!(c.controller.rate_hz, 5000.0);
    assert_eq!(c.controller.damping, [true, true, false]);
    assert_eq!(c.controller.gains.vel_kp, [1000.0; 3]);
    assert_eq!(c.controller.gains.vel_ki, [100.0; 3]);
    assert!(c.controller.motors.iter().all(|m| m.tau_max == 80.0));
    assert_eq!(c.sequence.faults.wrinkle, FaultAction::Continue);
    assert_eq!(c.sequence.phases.len(), 2);
    assert_eq!(c.sequence.phases[0].command, Command::MoveTo { q: [0.2, 0.6, -0.4], duration: 1.0 });
    assert_eq!(c.sequence.phases[1].payload_kg, Some(2.0));
    assert_eq!(c.obstacles.len(), 1);
    assert_eq!(s.noise.encoder_rad, 0.001);
    assert_eq!(s.noise.imu_m_s2, 0.05);
    assert_eq!(s.noise.torque_nm, 0.1);
    assert_eq!(s.noise.mocap_m, 0.002);
    assert_eq!(s.log.viz_rate_hz, 25.0);
    assert_eq!(s.log.flush_every_s, 0.5);
    assert_eq!(s.log.compression, Compression::Lz4);
    assert_eq!(s.log.chunk_size_bytes, 65536);
    assert_eq!(s.log.topics, ["joints", "events"]);
    assert_eq!(s.seed, 42);
    let m = s.model().unwrap();
    assert_eq!(m.options.dt, 2e-4);
    assert_eq!(m.gravity.norm(), 0.0);
}

#[test]
fn defaults_hold_q0_with_the_arms_parameters() {
    let s = parse("duration_s = 1.0\nq0 = [0.0, 0.5, -0.3]\n").unwrap();
    assert_eq!(s.closed.sequence.phases.len(), 1);
    let ph = &s.closed.sequence.phases[0];
    assert_eq!(ph.command, Command::Hold);
    assert!(ph.payload_kg.is_none() && ph.pressure_pa.is_none() && ph.damping.is_none());
    assert_eq!(ph.until.max_time, f64::INFINITY);
    assert_eq!(s.closed.q0, [0.0, 0.5, -0.3]);
    assert_eq!(s.arm_name, "popup-lab");
    assert_eq!(s.options.dt, 1e-4, "dt defaults to the controller period (10 kHz)");
    assert!(!s.options.disable.gravity);
    assert_eq!(s.params.payload_kg, 2.0);
    assert_eq!(s.params.pressure_pa, [30e3, 30e3]);
    assert_eq!(s.closed.sample_period, 0.01);
    assert_eq!(s.log.topics.len(), TOPICS.len());
    assert_eq!(s.log.viz_rate_hz, 30.0);
    assert_eq!(s.log.compression, Compression::Zstd);
    assert_eq!(s.log.chunk_size_bytes, 1 << 20);
    assert_eq!(s.noise.imu_m_s2, 0.0);
    assert_eq!(s.seed, 0);
    // a 2 kHz controller without dt: dt = 5e-4
    let s = parse("duration_s = 1.0\n[controller]\nrate_hz = 2000.0\n").unwrap();
    assert_eq!(s.options.dt, 5e-4);
    // a single pressure applies to both links
    assert_eq!(parse("duration_s = 1.0\npressure_pa = 40000.0\n").unwrap().params.pressure_pa, [40e3; 2]);
}

/// Lines and keys of the problems, for assertions.
fn found(p: &[Problem]) -> Vec<(usize, String)> {
    p.iter().map(|p| (p.line, p.key.clone())).collect()
}

#[test]
fn every_problem_is_reported_with_its_line_and_key() {
    let text = r#"format = "popup-scenario/1"
duration_s = 10.0
payload_kg = -1.0
pressure_pa = [30000.0, -5.0]
q0 = [0.0, 0.5]
dt = 1e-4
sample_rate_hz = 300.0

[effects.joint_friction]
tau_c = [0.5, 0.5, -0.5]
[effects.no_such_effect]
x = 1.0

[noise]
imu_m_s2 = -0.1

[log]
viz_rate_hz = 30.0
topics = ["joints", "tf"]
compression = "gzip"

[controller]
rate_hz = 3000.0
[controller.gains]
vel_kp = [5000.0, nan, 5000.0]

[[phases]]
kind = "ready"
until = { min_time = -1.0 }
[[phases]]
kind = "moving"
[[phases]]
kind = "holding"
[[phases]]
kind = "grasping"

[[obstacles]]
name = "ball"
sphere = { center = [0.0, 0.0, 1.0], radius = -0.1 }
"#;
    let problems = parse(text).unwrap_err();
    let got = found(&problems);
    let want: &[(usize, &str)] = &[
        (3, "payload_kg"),
        (4, "pressure_pa[1]"),
        (5, "q0"),
        (7, "sample_rate_hz"),
        (10, "effects.joint_friction.tau_c[2]"),
        (11, "effects.no_such_effect"),
        (15, "noise.imu_m_s2"),
        (19, "log.topics[1]"),
        (20, "log.compression"),
        (23, "controller.rate_hz"),
        (25, "controller.gains.vel_kp[1]"),
        (29, "phases[0].until"),
        (30, "phases[1]"),
        (34, "phases[3]"),
        (37, "obstacles[0]"),
    ];
    for (line, key) in want {
        assert!(got.iter().any(|(l, k)| l == line && k == key), "missing {line} {key} in\n{}", problems.iter().map(|p| p.to_string()).collect::<Vec<_>>().join("\n"));
    }
    assert_eq!(problems.len(), want.len(), "{problems:#?}");
    // sorted by line, and displayed as file:line: key: message
    assert!(problems.windows(2).all(|w| w[0].line <= w[1].line));
    let p = problems.iter().find(|p| p.key == "phases[3]").unwrap();
    assert!(p.to_string().starts_with("s.toml:34: phases[3]: ") && p.message.contains("payload_kg"), "{p}");
    let p = problems.iter().find(|p| p.key == "phases[1]").unwrap();
    assert!(p.message.contains("needs a motion"), "{p}");
    let p = problems.iter().find(|p| p.key == "sample_rate_hz").unwrap();
    assert!(p.message.contains("whole multiple"), "{p}");
    let p = problems.iter().find(|p| p.key == "controller.rate_hz").unwrap();
    assert!(p.message.contains("controller period"), "{p}");
}

#[test]
fn a_syntax_error_is_one_problem_at_its_line() {
    let p = parse("duration_s = 1.0\n[controller]\nrate_hz = = 3\n").unwrap_err();
    assert_eq!(p.len(), 1);
    assert_eq!(p[0].line, 3);
    assert_eq!(p[0].file, "s.toml");
    assert!(p[0].to_string().starts_with("s.toml:3: "), "{}", p[0]);
}

#[test]
fn unknown_and_mistyped_keys_are_named() {
    let p = parse("duration_s = 1.0\nspeed = 3\n[controller]\nrate = 5\nrate_hz = \"fast\"\n[log]\nzip = true\n").unwrap_err();
    let got = found(&p);
    assert!(got.contains(&(2, "speed".into())), "{p:#?}");
    assert!(p[0].message.contains("known keys") && p[0].message.contains("duration_s"), "{}", p[0]);
    assert!(got.contains(&(4, "controller.rate".into())), "{p:#?}");
    assert!(got.contains(&(5, "controller.rate_hz".into())), "{p:#?}");
    assert!(got.contains(&(7, "log.zip".into())), "{p:#?}");
    assert_eq!(p.len(), 4);
    // a missing duration and a wrong format
    let p = parse("format = \"popup-scenario/9\"\n").unwrap_err();
    assert_eq!(found(&p), [(0, "duration_s".to_string()), (1, "format".to_string())]);
    assert!(p[1].message.contains(SCENARIO_FORMAT));
    // a mistyped value inside a phase's signal names the key inside the phase
    let p = parse("duration_s = 1.0\n[[phases]]\nkind = \"moving\"\ntrack = [{ kind = \"const\", value = 0.0 }, { kind = \"step\", from = 0.0, to = 1.0, dleay = 1.0 }, { kind = \"const\", value = 0.0 }]\n").unwrap_err();
    assert_eq!(p.len(), 1);
    assert_eq!((p[0].line, p[0].key.as_str()), (4, "phases[0].track[1].dleay"), "{}", p[0]);
}

#[test]
fn an_arm_file_is_found_relative_to_the_scenario() {
    let dir = std::env::temp_dir().join(format!("popup-scenario-test-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("arms")).unwrap();
    std::fs::write(dir.join("arms/light.toml"), "base = \"popup-lab\"\nname = \"light\"\n[payload]\ndefault_kg = 0.5\n").unwrap();
    let path = dir.join("run.toml");
    std::fs::write(&path, "arm = \"arms/light.toml\"\nduration_s = 1.0\n[effects.air_drag]\ncd = 1.2\n").unwrap();
    let s = Scenario::read(&path).unwrap_or_else(|p| panic!("{p:#?}"));
    assert_eq!(s.arm.name, "light");
    assert_eq!(s.arm_name, "arms/light.toml");
    assert_eq!(s.arm_file.as_deref(), Some(dir.join("arms/light.toml").as_path()));
    assert_eq!(s.params.payload_kg, 0.5);
    assert_eq!(s.params.effects.air_drag.cd, 1.2);
    assert_eq!(s.source, path.display().to_string());
    // from another folder the same file name is not found
    let p = Scenario::parse(&s.text, "x.toml", Path::new("/nonexistent")).unwrap_err();
    assert_eq!(found(&p), [(1, "arm".to_string())]);
    assert!(p[0].message.contains("popup-lab"), "{}", p[0]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cartesian_targets_out_of_reach_are_refused_at_parse_time() {
    let text = "duration_s = 1.0\n[[phases]]\nkind = \"moving\"\ncartesian = { target = [-0.8, -0.8, 0.9] }\n";
    let p = parse(text).unwrap_err();
    assert_eq!(found(&p), [(4, "phases[0].cartesian.target".to_string())]);
}

#[test]
fn a_step_too_large_for_the_arm_is_found_at_parse_time() {
    let p = parse("duration_s = 1.0\ndt = 0.05\nsample_rate_hz = 20.0\n[controller]\nrate_hz = 20.0\n").unwrap_err();
    assert_eq!(found(&p), [(2, "dt".to_string())], "{p:#?}");
    assert!(p[0].message.contains("too large"), "{}", p[0]);
}

#[test]
fn set_key_edits_the_text_in_place() {
    let text = "# my run\nduration_s = 1.0 # comment kept\npressure_pa = [30000.0, 30000.0]\nseed = 3\n\n[controller]\nrate_hz = 10000.0\n\n[[phases]]\nkind = \"ready\"\nuntil = { min_time = 1.0 }\n";
    // an existing scalar
    let t = set_key(text, "duration_s", 2.5).unwrap();
    assert!(t.contains("duration_s = 2.5 # comment kept") && t.starts_with("# my run\n"), "{t}");
    assert_eq!(parse(&t).unwrap().closed.duration, 2.5);
    // a scalar broadcast over an array, and one element
    let t = set_key(text, "pressure_pa", 40000.0).unwrap();
    assert_eq!(parse(&t).unwrap().params.pressure_pa, [40e3, 40e3]);
    let t = set_key(&t, "pressure_pa[1]", 50000.0).unwrap();
    assert_eq!(parse(&t).unwrap().params.pressure_pa, [40e3, 50e3]);
    // an integer stays an integer
    let t = set_key(text, "seed", 7.0).unwrap();
    assert!(t.contains("seed = 7\n"), "{t}");
    assert_eq!(parse(&t).unwrap().seed, 7);
    // missing keys: top level, in an existing table, in tables that do not exist yet, in an
    // array element's inline table
    let t = set_key(text, "payload_kg", 0.5).unwrap();
    let t = set_key(&t, "controller.gains.vel_kp", 1234.0).unwrap();
    let t = set_key(&t, "effects.joint_friction.tau_c", 0.25).unwrap();
    let t = set_key(&t, "phases[0].until.max_time", 9.0).unwrap();
    let t = set_key(&t, "noise.imu_m_s2", 0.01).unwrap();
    let s = parse(&t).unwrap_or_else(|p| panic!("{p:#?}\n{t}"));
    assert_eq!(s.params.payload_kg, 0.5);
    assert_eq!(s.closed.controller.gains.vel_kp, [1234.0; 3]);
    assert_eq!(s.params.effects.joint_friction.tau_c, [0.25; 3]);
    assert_eq!(s.closed.sequence.phases[0].until.max_time, 9.0);
    assert_eq!(s.closed.sequence.phases[0].until.min_time, 1.0);
    assert_eq!(s.noise.imu_m_s2, 0.01);
    assert!(t.starts_with("# my run\n"), "{t}");
    // an existing table reached through a sub-table header only
    let t2 = set_key("duration_s = 1.0\n[controller.gains]\nvel_kp = 1.0\n", "controller.rate_hz", 2000.0).unwrap();
    assert_eq!(parse(&t2).unwrap().closed.controller.rate_hz, 2000.0);
    // errors: through a non-table, into a non-array, past the end, a string, bad path
    for (path, why) in [
        ("duration_s.x", "not a table"),
        ("controller[0]", "not an array"),
        ("pressure_pa[2]", "no index 2"),
        ("phases[0].kind", "not a number"),
        ("phases.kind", "not a table"),
        ("a..b", "malformed"),
        ("log.topics[0]", "cannot create"),
    ] {
        let e = set_key(text, path, 1.0).unwrap_err();
        assert!(e.message.contains(why), "{path}: {e}");
        assert_eq!(e.key, path);
    }
}

#[test]
fn sweep_values_are_ranges_or_lists() {
    assert_eq!(parse_values("0:2:0.5").unwrap(), [0.0, 0.5, 1.0, 1.5, 2.0]);
    assert_eq!(parse_values("0,1,2.5").unwrap(), [0.0, 1.0, 2.5]);
    assert_eq!(parse_values("3").unwrap(), [3.0]);
    let v = parse_values("0:1:0.1").unwrap();
    assert_eq!(v.len(), 11);
    assert_eq!(*v.last().unwrap(), 1.0);
    assert_eq!(parse_values("0:1:0.3").unwrap().len(), 4);
    assert_eq!(parse_values("2:0:-1").unwrap(), [2.0, 1.0, 0.0]);
    for bad in ["0:1:0", "0:1:-0.5", "0:1", "a,b", "1,,2", "0:inf:1", "0:1e9:1e-3"] {
        assert!(parse_values(bad).is_err(), "{bad}");
    }
}

#[test]
fn the_experiment_toml_is_a_reference_replay_run() {
    let s = parse(FULL).unwrap();
    let t: toml::Table = toml::from_str(&s.experiment_toml()).unwrap_or_else(|e| panic!("{e}\n{}", s.experiment_toml()));
    assert_eq!(t["format"].as_str(), Some("popup-run/1"));
    assert_eq!(t["replay"].as_str(), Some("reference"));
    assert_eq!(t["arm"].as_str(), Some("popup-lab"));
    assert_eq!(t["payload_kg"].as_float(), Some(1.5));
    assert_eq!(t["gravity"].as_bool(), Some(false));
    assert_eq!(t["description"].as_str(), Some("full"));
    let p = t["pressure_pa"].as_array().unwrap();
    assert_eq!(p[1].as_float(), Some(50e3));
    let c = t["controller"].as_table().unwrap();
    assert_eq!(c["rate_hz"].as_float(), Some(5000.0));
    assert_eq!(c["gains"]["vel_kp"].as_float(), Some(1000.0));
    assert_eq!(c["motor"]["tau_max"].as_float(), Some(80.0));
    // the defaults give an empty controller table
    let d: toml::Table = toml::from_str(&parse("duration_s = 1.0\n").unwrap().experiment_toml()).unwrap();
    assert!(d["controller"].as_table().unwrap().is_empty());
}

#[test]
fn the_bundled_examples_parse() {
    let hold = Scenario::read(&examples().join("hold_1h.toml")).unwrap_or_else(|p| panic!("{p:#?}"));
    assert_eq!(hold.closed.duration, 3600.0);
    assert_eq!(hold.options.dt, 5e-4);
    assert_eq!(hold.closed.controller.rate_hz, 2000.0);
    assert_eq!(hold.params.payload_kg, 1.0);
    assert_eq!(hold.closed.sequence.phases.len(), 1);
    let pick = Scenario::read(&examples().join("pick_and_place.toml")).unwrap_or_else(|p| panic!("{p:#?}"));
    let kinds: Vec<&str> = pick.closed.sequence.phases.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(kinds, ["ToPick", "Grasping", "ToPlace", "Releasing", "Back", "Holding"]);
    assert_eq!(pick.closed.sequence.phases[1].payload_kg, Some(1.0));
    assert_eq!(pick.closed.controller.damping, [true; 3]);
}

#[test]
fn the_hold_example_holds_still_at_2_khz() {
    // the first 10 s of the one-hour benchmark: stable and settled at q0
    let mut s = Scenario::read(&examples().join("hold_1h.toml")).unwrap();
    s.closed.duration = 10.0;
    let m = s.model().unwrap();
    let r = run_closed_loop(&m, &s.params, &s.closed).unwrap();
    assert_eq!(r.status, Status::Completed);
    let nch = popup_core::sensor::NCH;
    let n = r.traj.data.len() / nch;
    let last = &r.traj.data[(n - 1) * nch..n * nch];
    for (j, q0) in s.closed.q0.iter().enumerate() {
        assert!((last[1 + j] - q0).abs() < 2e-3, "q{} = {} vs {q0}", j + 1, last[1 + j]);
        assert!(last[4 + j].abs() < 1e-2, "dq{} = {}", j + 1, last[4 + j]);
    }
}
