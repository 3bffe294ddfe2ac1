//! `popup`: the headless command-line front of popup-core.
//!
//! Headless runs from scenario files logged to MCAP (`run`), parameter grids (`sweep`),
//! scenario validation (`check`), and the arm tools (`arm`, `statics`, `hold`, `info`).
//! Exit codes: 0 success; 1 the run failed (went unstable, a log write failed, runs of a
//! sweep failed); 2 usage error or invalid input (every problem of a scenario is listed);
//! 130 / 143 interrupted by SIGINT / SIGTERM (the log is finished properly).
//!
//! The CLI is a library so that two front ends share it: the `popup` binary of this crate
//! (`src/main.rs`) and the Python package's `popup` command, which routes its non-Python
//! subcommands here through `popup._core.run_cli`. [`run_from_args`] therefore never exits
//! the process: it prints help and errors itself and returns the exit code.

use clap::{Parser, Subcommand};
use popup_core::drive::{Drive, Linear3};
use popup_core::math::VecN;
use popup_core::model::{Integrator, Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::{CHANNELS, NCH};
use popup_core::sim::{rest_state, run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::{gravity_torque, locked_modes};
use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};

pub mod execute;
pub mod progress;
pub mod sweep;

use popup_core::scenario::Scenario;
use progress::{Mode, Progress, StopFlags};

#[derive(Parser)]
#[command(name = "popup", version, about = "Simulation of inflatable robot arms (headless)")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(clap::Args, Clone)]
struct ArmArgs {
    /// Arm: a built-in name (`popup info` lists them, packaged arm files such as
    /// `popup-lab-thesis` included) or the path of a TOML arm file.
    #[arg(long, default_value = "popup-lab")]
    arm: String,
    /// Payload [kg] (default: the arm's).
    #[arg(long)]
    payload_kg: Option<f64>,
    /// Link pressures [Pa], e.g. `--pressure-pa 30000,30000` (default: the arm's).
    #[arg(long, value_delimiter = ',')]
    pressure_pa: Option<Vec<f64>>,
    /// Motor angles q1,q2,q3 [rad].
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.0, 0.0], allow_hyphen_values = true)]
    q: Vec<f64>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Print version, build profile and features.
    Info,
    /// Run a scenario headless and log it to an MCAP file (open it in Foxglove).
    Run {
        /// Scenario file (TOML, docs/logging.md).
        scenario: PathBuf,
        /// MCAP output path.
        #[arg(long)]
        out: PathBuf,
        /// Simulated time [s] (default: the scenario's duration_s).
        #[arg(long)]
        duration: Option<f64>,
        /// Seed of the sensor noise (default: the scenario's seed).
        #[arg(long)]
        seed: Option<u64>,
        /// Progress display: a bar on a terminal (auto), a line per flush (lines), none.
        #[arg(long, value_enum, default_value_t = Mode::Auto)]
        progress: Mode,
    },
    /// Run a grid of scenario variants in parallel; writes DIR/summary.csv (one row per run).
    Sweep {
        /// Scenario file.
        scenario: PathBuf,
        /// KEY=START:STOP:STEP or KEY=V1,V2,... for any numeric key of the scenario
        /// (payload_kg, pressure_pa, pressure_pa[1], controller.gains.vel_kp, ...); repeat for a grid.
        #[arg(long = "param", required = true)]
        params: Vec<String>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Also write one MCAP log per run (DIR/run_NNNN.mcap).
        #[arg(long)]
        mcap: bool,
        /// Worker threads (0 = all cores; more than the cores are capped at them, more than
        /// 4 per core refused).
        #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
        threads: i64,
        /// Simulated time per run [s] (default: the scenario's).
        #[arg(long)]
        duration: Option<f64>,
        /// Seed of the sensor noise, the same for every run (default: the scenario's).
        #[arg(long)]
        seed: Option<u64>,
        /// Also write DIR/summary.parquet (done by the Python front end, `pip install`ed
        /// `popup`; this binary alone writes summary.csv and refuses the flag).
        #[arg(long)]
        parquet: bool,
    },
    /// Validate a scenario file and list every problem (file:line: key: message).
    Check {
        /// Scenario file.
        scenario: PathBuf,
    },
    /// Print the complete TOML of an arm (built-in name or file), e.g. to start an arm file.
    Arm {
        /// Built-in name (`popup info` lists them) or path of an arm file.
        #[arg(default_value = "popup-lab")]
        arm: String,
    },
    /// Static equilibrium and locked-motor modes at a pose.
    Statics {
        #[command(flatten)]
        a: ArmArgs,
    },
    /// Torque-driven run holding the arm at a pose (gravity-compensating torques plus an
    /// optional initial bending velocity), written as CSV with the sensor channels.
    Hold {
        #[command(flatten)]
        a: ArmArgs,
        /// Simulated time [s].
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Physics step [s].
        #[arg(long, default_value_t = 1e-3)]
        dt: f64,
        /// Integrator: rk4 or semi_implicit.
        #[arg(long, default_value = "rk4")]
        integrator: String,
        /// Output sample rate [Hz].
        #[arg(long, default_value_t = 100.0)]
        sample_rate: f64,
        /// Initial rate of joint d22 [rad/s] (a tip kick to watch the ring-down).
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        kick: f64,
        /// CSV output path (`-` = stdout).
        #[arg(long, default_value = "-")]
        out: String,
    },
}

/// The arm of `--arm` / `popup arm NAME`: a built-in or packaged arm by name, else an arm
/// file (relative to the working directory): [`ArmSpec::resolve`], as for scenario files
/// and `popup.Model(name)`.
fn load_arm(name: &str) -> popup_core::Result<ArmSpec> {
    ArmSpec::resolve(name, Path::new("")).map(|(a, _)| a)
}

fn params(spec: &ArmSpec, a: &ArmArgs) -> popup_core::Result<Params> {
    if a.q.len() != 3 {
        return Err(popup_core::Error::input("--q", format!("expected 3 motor angles q1,q2,q3 [rad], got {}", a.q.len())));
    }
    if a.pressure_pa.as_ref().is_some_and(|p| p.len() != 2) {
        return Err(popup_core::Error::input("--pressure-pa", "expected 2 pressures p1,p2 [Pa]"));
    }
    let p = a.pressure_pa.clone().unwrap_or_else(|| vec![spec.links[0].pressure_pa, spec.links[1].pressure_pa]);
    Ok(Params { payload_kg: a.payload_kg.unwrap_or(spec.payload.default_kg), pressure_pa: [p[0], p[1]], effects: spec.effects })
}

/// Run the CLI on a full argument vector (`args[0]` is the program name, as in
/// `std::env::args_os()`) and return the process exit code: 0 on success and for
/// `--help`/`--version`, 2 for usage errors (clap) and for failed commands (`popup: error: ...`
/// on stderr). Output goes to the process's stdout/stderr, flushed before returning.
/// Never calls `std::process::exit`.
pub fn run_from_args<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let code = match Cli::try_parse_from(args) {
        // help, version and usage errors; clap picks stdout/stderr and the code (0 or 2)
        Err(e) => {
            let _ = e.print();
            e.exit_code()
        }
        Ok(cli) => match go(cli) {
            Ok(code) => code,
            Err(e) => {
                eprintln!("popup: error: {e}");
                match e {
                    popup_core::Error::Log { .. } => 1,
                    _ => 2,
                }
            }
        },
    };
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    code
}

/// Read a scenario, or print every problem (`file:line: key: message`) and return None.
fn read_scenario(path: &Path) -> Option<Scenario> {
    match Scenario::read(path) {
        Ok(sc) => Some(sc),
        Err(ps) => {
            for p in &ps {
                eprintln!("popup: error: {p}");
            }
            eprintln!("popup: {} problem{} in {}", ps.len(), if ps.len() == 1 { "" } else { "s" }, path.display());
            None
        }
    }
}

fn run_scenario(path: &Path, out: &Path, duration: Option<f64>, seed: Option<u64>, mode: Mode) -> popup_core::Result<i32> {
    let Some(mut sc) = read_scenario(path) else { return Ok(2) };
    if let Some(d) = duration {
        sc.closed.duration = execute::check_duration("--duration", d)?;
    }
    if let Some(s) = seed {
        sc.seed = s;
    }
    for w in sc.nonfinite_warnings() {
        eprintln!("popup: warning: {}: {w}", path.display());
    }
    let (stop, armed) = StopFlags::register();
    let mut prog = Progress::new(mode, sc.closed.duration, sc.log.flush_every_s, stop.clone());
    let mut extra = std::collections::BTreeMap::new();
    extra.insert("command".to_string(), format!("popup run {} --out {}", path.display(), out.display()));
    extra.insert("dt".to_string(), sc.options.dt.to_string());
    extra.insert("sample_rate_hz".to_string(), (1.0 / sc.closed.sample_period).to_string());
    let res = execute::execute(&sc, Some(out), &mut prog, extra, None);
    drop(armed);
    let o = res?;
    for w in &o.warnings {
        eprintln!("popup: warning: {w}");
    }
    let m = &o.metrics;
    eprintln!(
        "popup: {} at t = {} s: {} samples -> {} (peak |M|/M_w {:.3}, {:.3}; {} wrinkling alarm{}{})",
        o.status.name(),
        m.t_last,
        m.samples,
        out.display(),
        m.peak_ratio[0],
        m.peak_ratio[1],
        m.wrinkle_alarms,
        if m.wrinkle_alarms == 1 { "" } else { "s" },
        if o.nonfinite > 0 { format!("; {} non-finite values left out of the log (their samples kept)", o.nonfinite) } else { String::new() }
    );
    Ok(match o.status {
        popup_core::control::closed_loop::Status::Completed => 0,
        popup_core::control::closed_loop::Status::Unstable => 1,
        popup_core::control::closed_loop::Status::Interrupted => stop.exit_code(),
    })
}

fn go(cli: Cli) -> popup_core::Result<i32> {
    match cli.cmd {
        Cmd::Run { scenario, out, duration, seed, progress } => return run_scenario(&scenario, &out, duration, seed, progress),
        Cmd::Check { scenario } => {
            let Some(sc) = read_scenario(&scenario) else { return Ok(2) };
            for w in sc.nonfinite_warnings() {
                eprintln!("popup: warning: {}: {w}", scenario.display());
            }
            println!(
                "{}: ok: arm {}, payload {} kg, pressures {:?} Pa, {} phase{}, {} s at dt = {} s, sensors at {} Hz",
                scenario.display(),
                sc.arm_name,
                sc.params.payload_kg,
                sc.params.pressure_pa,
                sc.closed.sequence.phases.len(),
                if sc.closed.sequence.phases.len() == 1 { "" } else { "s" },
                sc.closed.duration,
                sc.options.dt,
                1.0 / sc.closed.sample_period
            );
        }
        Cmd::Sweep { parquet: true, .. } => {
            return Err(popup_core::Error::input(
                "--parquet",
                "the Parquet summary is written by the Python front end (the `popup` command `pip install` puts on PATH); this binary writes summary.csv only",
            ))
        }
        Cmd::Sweep { scenario, params, out, mcap, threads, duration, seed, parquet: false } => {
            let threads = popup_core::limits::threads("--threads", threads)?;
            let axes = params.iter().map(|p| sweep::parse_axis(p)).collect::<popup_core::Result<Vec<_>>>()?;
            if let Some(d) = duration {
                execute::check_duration("--duration", d)?;
            }
            let (stop, armed) = StopFlags::register();
            let res = sweep::sweep(&scenario, &axes, &out, mcap, threads, duration, seed, &stop);
            drop(armed);
            let failed = res?;
            let n: usize = axes.iter().map(|a| a.values.len()).product();
            eprintln!("popup: {n} runs, {failed} not completed -> {}", out.join("summary.csv").display());
            if stop.raised() {
                return Ok(stop.exit_code());
            }
            return Ok(i32::from(failed > 0));
        }
        Cmd::Info => {
            println!("popup {}", popup_core::VERSION);
            println!("build profile: {}", if cfg!(debug_assertions) { "debug" } else { "release" });
            println!("features: {}", popup_core::BUILD_FEATURES.join(", "));
            println!("built-in arms: {}", ArmSpec::BUILTIN.join(", "));
            println!("scenario format: {}; log: MCAP (zstd, lz4), Foxglove JSON schemas", popup_core::scenario::SCENARIO_FORMAT);
        }
        Cmd::Arm { arm } => print!("{}", load_arm(&arm)?.to_toml()),
        Cmd::Statics { a } => {
            let spec = load_arm(&a.arm)?;
            let model = Model::compile(&spec, Options::default())?;
            let pd = ParamData::new(&model, &params(&spec, &a)?)?;
            for w in &pd.warnings {
                eprintln!("popup: warning: {w}");
            }
            let st = rest_state(&model, &pd, 0.0, [a.q[0], a.q[1], a.q[2]])?;
            println!("arm {} payload {} kg pressures {:?} Pa", spec.name, pd.params.payload_kg, pd.params.pressure_pa);
            for (i, j) in model.joints.iter().enumerate() {
                println!("  {:>4} = {:+.6} rad", j.name, st.q[i]);
            }
            let g = gravity_torque(&model, &pd, &st.q);
            println!("holding torques [N·m]: {:?}", model.motor_idx.map(|i| g[i]));
            println!("locked-motor modes [rad/s]: {:?}", locked_modes(&model, &pd, &st.q));
            println!("wrinkling moment M_w [N·m] (coefficient {:.4}): {:?}", model.wrinkle_coef, pd.mw);
        }
        Cmd::Hold { a, duration, dt, integrator, sample_rate, kick, out } => {
            let spec = load_arm(&a.arm)?;
            let model = Model::compile(&spec, Options { dt, integrator: Integrator::parse(&integrator)?, ..Options::default() })?;
            let pd = ParamData::new(&model, &params(&spec, &a)?)?;
            for w in &pd.warnings {
                eprintln!("popup: warning: {w}");
            }
            let mut st = rest_state(&model, &pd, 0.0, [a.q[0], a.q[1], a.q[2]])?;
            let g = gravity_torque(&model, &pd, &st.q);
            let hold = model.motor_idx.map(|i| g[i]);
            st.v = VecN::zeros();
            st.v[model.root_bend_idx[3]] = kick;
            let cfg = RunConfig {
                drive: Drive::Torque(Linear3::new(&[0.0], &[hold])?),
                initial: Some(st),
                duration: Some(duration),
                sample_period: 1.0 / sample_rate,
                check_step: true,
            };
            let tr = run(&model, &pd, &cfg)?;
            let mut w: Box<dyn Write> = if out == "-" {
                Box::new(std::io::BufWriter::new(std::io::stdout()))
            } else {
                Box::new(std::io::BufWriter::new(
                    std::fs::File::create(&out).map_err(|e| popup_core::Error::input("--out", format!("{out}: {e}")))?,
                ))
            };
            let io = |e: std::io::Error| popup_core::Error::input("--out", e.to_string());
            writeln!(w, "{}", CHANNELS.join(",")).map_err(io)?;
            for r in tr.data.chunks(NCH) {
                let line: Vec<String> = r.iter().map(|x| format!("{x:.9e}")).collect();
                writeln!(w, "{}", line.join(",")).map_err(io)?;
            }
            w.flush().map_err(io)?;
            for al in &tr.alarms {
                eprintln!("popup: wrinkling alarm on link {} from t = {:.3} s (peak |M|/M_w = {:.2})", al.link, al.t_start, al.peak_ratio);
            }
        }
    }
    Ok(0)
}
