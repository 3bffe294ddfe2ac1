//! The MCAP logger on its own: non-finite values are left out and reported (never a
//! silent `null`; their finite siblings are kept), flushes close chunks so a cut file keeps them, and the decoded
//! messages of a logged closed-loop run equal its arrays.

#![cfg(feature = "mcap")]

use popup_core::control::closed_loop::{run_closed_loop, run_closed_loop_into, NCTRL};
use popup_core::control::machine::Command;
use popup_core::control::ClosedLoop;
use popup_core::log::{LogOptions, McapLogger, RunMeta};
use popup_core::model::{Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::{CHANNELS, NCH};
use popup_core::sim::rest_state;
use popup_core::spec::ArmSpec;
use popup_core::stream::{Collect, Sink, StateView, Tee};
use std::io::Cursor;

fn model(dt: f64) -> Model {
    Model::compile(&ArmSpec::builtin("popup-lab").unwrap(), Options { dt, ..Options::default() }).unwrap()
}

fn messages(bytes: &[u8]) -> Vec<(String, serde_json::Value)> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            (m.channel.topic.clone(), serde_json::from_slice(&m.data).unwrap())
        })
        .collect()
}

#[test]
fn non_finite_values_are_left_out_and_reported() {
    let m = model(1e-3);
    let pd = ParamData::new(&m, &Params::defaults(&m)).unwrap();
    let st = rest_state(&m, &pd, 0.0, [0.0, 0.5, -0.3]).unwrap();
    let mut buf = Cursor::new(Vec::new());
    {
        let mut lg = McapLogger::new(&mut buf, "mem.mcap", &m, &LogOptions::default(), &RunMeta::default(), 0.01, 0.05).unwrap();
        lg.state(&StateView { t: 0.0, q: &st.q, v: &st.v, pd: &pd, ratio: [0.5, 0.2] }).unwrap();
        for k in 0..4 {
            let mut row = [0.5; NCH];
            row[0] = k as f64 * 0.01;
            if k >= 2 {
                row[14] = f64::NAN; // imu1_ay
            }
            let mut c = [0.25; NCTRL];
            c[16] = f64::INFINITY; // d_min without obstacles: left out, not an error
            lg.sample(&row, Some(&c)).unwrap();
        }
        let end = lg.finish("completed").unwrap();
        assert_eq!(end.nonfinite_dropped, 2);
        assert_eq!(end.samples, 4);
    }
    let bytes = buf.into_inner();
    assert!(!bytes.windows(4).any(|w| w == b"null"));
    let msgs = messages(&bytes);
    let imu: Vec<_> = msgs.iter().filter(|(t, _)| t == "/popup/imu").collect();
    assert_eq!(imu.len(), 4, "issue 19: a NaN drops only its own key, not the sample");
    for (k, (_, v)) in imu.iter().enumerate() {
        assert_eq!(v.get("imu1_ay").is_none(), k >= 2, "{v}");
        assert_eq!(v["imu1_ax"], 0.5, "finite siblings survive: {v}");
    }
    assert_eq!(msgs.iter().filter(|(t, _)| t == "/popup/joints").count(), 4, "other topics keep them");
    let errors: Vec<_> = msgs.iter().filter(|(t, v)| t == "/log" && v["level"] == 4).collect();
    assert_eq!(errors.len(), 1, "reported once per topic");
    let text = errors[0].1["message"].as_str().unwrap();
    assert!(text.contains("imu1_ay") && text.contains("/popup/imu") && text.contains("t = 0.02"), "{text}");
    let ctrl = msgs.iter().find(|(t, _)| t == "/popup/control").unwrap();
    assert!(ctrl.1.get("d_min").is_none() && ctrl.1["phase"] == 0.25);
}

#[test]
fn logged_run_equals_its_arrays_and_flushes_close_chunks() {
    let m = model(5e-4);
    let mut cfg = ClosedLoop::single(Command::Hold, [0.0, 0.6, -0.4], 2.0, 0.01);
    cfg.controller.rate_hz = 2000.0;
    let p = Params::defaults(&m);
    let batch = run_closed_loop(&m, &p, &cfg).unwrap();
    let mut buf = Cursor::new(Vec::new());
    let opts = LogOptions { flush_every_s: 0.5, ..LogOptions::default() };
    let mut col = Collect::default();
    {
        let mut lg = McapLogger::new(&mut buf, "mem.mcap", &m, &opts, &RunMeta::default(), 0.01, 0.05).unwrap();
        let mut tee = Tee { a: &mut col, b: &mut lg };
        run_closed_loop_into(&m, &p, &cfg, &mut tee).unwrap();
        lg.finish("completed").unwrap();
    }
    // streamed = batch, bit for bit
    assert_eq!(col.data.len(), batch.traj.data.len());
    assert!(col.data.iter().zip(&batch.traj.data).all(|(a, b)| a.to_bits() == b.to_bits()));
    let bytes = buf.into_inner();
    let msgs = messages(&bytes);
    let joints: Vec<_> = msgs.iter().filter(|(t, _)| t == "/popup/joints").map(|(_, v)| v).collect();
    assert_eq!(joints.len(), batch.traj.nsample);
    let iq2 = CHANNELS.iter().position(|c| *c == "q2").unwrap();
    for (k, v) in joints.iter().enumerate() {
        assert_eq!(v["q2"].as_f64().unwrap().to_bits(), batch.traj.data[k * NCH + iq2].to_bits());
        assert_eq!(v["t"].as_f64().unwrap().to_bits(), batch.traj.data[k * NCH].to_bits());
    }
    // one chunk per flush interval at least: 2 s / 0.5 s
    let chunks = mcap::read::LinearReader::new(&bytes).unwrap().filter(|r| matches!(r, Ok(mcap::records::Record::Chunk { .. }))).count();
    assert!(chunks >= 4, "{chunks} chunks");
}
