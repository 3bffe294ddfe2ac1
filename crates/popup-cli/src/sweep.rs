//! `popup sweep`: a grid of scenario variants run in parallel, one summary table.

use crate::execute::{execute, Outcome};
use crate::progress::{Progress, StopFlags};
use popup_core::scenario::{parse_values, set_key, Scenario};
use popup_core::{Error, Result};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One swept key and its values.
#[derive(Debug, Clone)]
pub struct Axis {
    /// Key path in the scenario (`payload_kg`, `controller.gains.vel_kp`, ...).
    pub key: String,
    /// Values.
    pub values: Vec<f64>,
}

/// Parse `KEY=SPEC` (`SPEC`: `a:b:step` or `v1,v2,...`).
///
/// # Errors
/// [`Error::Input`] naming the argument.
pub fn parse_axis(arg: &str) -> Result<Axis> {
    let (k, v) = arg.split_once('=').ok_or_else(|| Error::input(format!("--param {arg}"), "expected KEY=START:STOP:STEP or KEY=V1,V2,..."))?;
    let values = parse_values(v).map_err(|m| Error::input(format!("--param {arg}"), m))?;
    Ok(Axis { key: k.trim().to_string(), values })
}

/// The grid points (row-major: the last axis varies fastest).
pub fn grid(axes: &[Axis]) -> Vec<Vec<f64>> {
    let mut pts = vec![Vec::new()];
    for a in axes {
        pts = pts.into_iter().flat_map(|p| a.values.iter().map(move |&v| [p.clone(), vec![v]].concat())).collect();
    }
    pts
}

/// The scenario text of one grid point.
fn variant(text: &str, axes: &[Axis], point: &[f64]) -> std::result::Result<String, String> {
    let mut t = text.to_string();
    for (a, &v) in axes.iter().zip(point) {
        t = set_key(&t, &a.key, v).map_err(|p| p.to_string())?;
    }
    Ok(t)
}

/// Run the sweep of `path` over `axes` on `threads` threads (0 = all cores): writes
/// `out/summary.csv` (and `out/run_NNNN.mcap` with `mcap`); returns the number of
/// failed runs. `duration`, `seed` override the scenario's.
///
/// # Errors
/// Unreadable scenario, a bad key, an unwritable output folder.
pub fn sweep(path: &Path, axes: &[Axis], out: &Path, mcap: bool, threads: usize, duration: Option<f64>, seed: Option<u64>, stop: &StopFlags) -> Result<usize> {
    let source = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(&source, format!("cannot read the scenario: {e}")))?;
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let pts = grid(axes);
    // every variant is checked before anything runs
    let mut scs = Vec::with_capacity(pts.len());
    for p in &pts {
        let txt = variant(&text, axes, p).map_err(|m| Error::input("--param", m))?;
        let mut sc = Scenario::parse(&txt, &source, &base).map_err(|ps| {
            let at: Vec<String> = axes.iter().zip(p).map(|(a, v)| format!("{}={v}", a.key)).collect();
            Error::input(format!("{source} at {}", at.join(", ")), ps.iter().map(|p| p.to_string()).collect::<Vec<_>>().join("; "))
        })?;
        if let Some(d) = duration {
            sc.closed.duration = d;
        }
        if let Some(s) = seed {
            sc.seed = s;
        }
        scs.push(sc);
    }
    std::fs::create_dir_all(out).map_err(|e| Error::input("--out", format!("{}: {e}", out.display())))?;
    let job = |i: usize| -> Result<Outcome> {
        if stop.raised() {
            return Err(Error::input("sweep", "skipped: the sweep was interrupted before this run started"));
        }
        let log: Option<PathBuf> = mcap.then(|| out.join(format!("run_{i:04}.mcap")));
        let mut extra = BTreeMap::new();
        for (a, v) in axes.iter().zip(&pts[i]) {
            extra.insert(format!("sweep.{}", a.key), v.to_string());
        }
        execute(&scs[i], log.as_deref(), &mut Progress::silent(stop.clone()), extra, None)
    };
    let run_all = || (0..pts.len()).into_par_iter().map(job).collect::<Vec<_>>();
    let results = if threads == 0 {
        run_all()
    } else {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| Error::input("--threads", e.to_string()))?.install(run_all)
    };
    let csv = out.join("summary.csv");
    let io = |e: std::io::Error| Error::Log { path: csv.display().to_string(), message: e.to_string() };
    let mut w = std::io::BufWriter::new(std::fs::File::create(&csv).map_err(io)?);
    let mut head = vec!["run".to_string()];
    head.extend(axes.iter().map(|a| a.key.clone()));
    head.extend(
        [
            "seed", "status", "t_end", "samples", "peak_m1_ratio", "peak_m2_ratio", "rms_track_q1", "rms_track_q2", "rms_track_q3", "peak_tau1", "peak_tau2", "peak_tau3", "ee_x",
            "ee_y", "ee_z", "wrinkle_alarms", "faults", "nonfinite_dropped", "error",
        ]
        .map(String::from),
    );
    writeln!(w, "{}", head.join(",")).map_err(io)?;
    let mut failed = 0;
    for (i, (p, r)) in pts.iter().zip(&results).enumerate() {
        let mut row: Vec<String> = vec![i.to_string()];
        row.extend(p.iter().map(|v| v.to_string()));
        row.push(scs[i].seed.to_string());
        match r {
            Ok(o) => {
                let m = &o.metrics;
                row.push(o.status.name().into());
                row.extend([m.t_last, m.samples as f64, m.peak_ratio[0], m.peak_ratio[1]].iter().map(|v| v.to_string()));
                row.extend(m.rms_track().iter().chain(&m.peak_tau).chain(&m.ee).map(|v| v.to_string()));
                row.extend([m.wrinkle_alarms, m.faults, o.nonfinite].map(|v| v.to_string()));
                row.push(String::new());
                if o.status.name() != "completed" {
                    failed += 1;
                }
            }
            Err(e) => {
                failed += 1;
                row.push("error".into());
                row.extend(std::iter::repeat_n(String::new(), 16));
                row.push(format!("\"{}\"", e.to_string().replace('"', "'")));
            }
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.flush().map_err(io)?;
    Ok(failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_is_row_major() {
        let a = [Axis { key: "a".into(), values: vec![1.0, 2.0] }, Axis { key: "b".into(), values: vec![10.0, 20.0, 30.0] }];
        let g = grid(&a);
        assert_eq!(g.len(), 6);
        assert_eq!(g[0], vec![1.0, 10.0]);
        assert_eq!(g[1], vec![1.0, 20.0]);
        assert_eq!(g[5], vec![2.0, 30.0]);
    }

    #[test]
    fn bad_axis_is_named() {
        let e = parse_axis("payload_kg").unwrap_err().to_string();
        assert!(e.contains("--param payload_kg") && e.contains("KEY="), "{e}");
        assert_eq!(parse_axis("payload_kg=0:1:0.5").unwrap().values, vec![0.0, 0.5, 1.0]);
    }
}
