//! `popup`: the headless command-line front of popup-core.
//!
//! This first version covers arm files, statics and long torque-driven runs written to CSV;
//! scenario files, sweeps and MCAP logging come with later issues.
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

#[derive(Parser)]
#[command(name = "popup", version, about = "Simulation of inflatable robot arms (headless)")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(clap::Args, Clone)]
struct ArmArgs {
    /// Built-in arm name or path to a TOML arm file.
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
    /// Print the complete TOML of an arm (built-in name or file), e.g. to start an arm file.
    Arm {
        /// Built-in name or path.
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

fn load_arm(name: &str) -> popup_core::Result<ArmSpec> {
    if ArmSpec::BUILTIN.contains(&name) {
        return ArmSpec::builtin(name);
    }
    match std::fs::read_to_string(name) {
        Ok(text) => ArmSpec::from_toml(&text, name),
        Err(e) if std::path::Path::new(name).exists() => Err(popup_core::Error::ArmFile { source_name: name.into(), message: e.to_string() }),
        Err(_) => ArmSpec::builtin(name),
    }
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
            Ok(()) => 0,
            Err(e) => {
                eprintln!("popup: error: {e}");
                2
            }
        },
    };
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    code
}

fn go(cli: Cli) -> popup_core::Result<()> {
    match cli.cmd {
        Cmd::Info => {
            println!("popup {}", popup_core::VERSION);
            println!("build profile: {}", if cfg!(debug_assertions) { "debug" } else { "release" });
            println!("features: {}", popup_core::BUILD_FEATURES.join(", "));
            println!("built-in arms: {}", ArmSpec::BUILTIN.join(", "));
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
    Ok(())
}
