//! The independent reference table of `reference-arm.md` (equilibria, tip sag, locked-motor
//! modes at 30 kPa, gravity on), reproduced within its tolerances: 1e-4 rad, 0.5 mm, 0.5 %.

use popup_core::kinematics::prbm::end_effector;
use popup_core::math::VecN;
use popup_core::model::{Model, Options};
use popup_core::params::{Flex, ParamData, Params};
use popup_core::sim::rest_state;
use popup_core::spec::ArmSpec;
use std::f64::consts::FRAC_PI_2;

struct Row {
    payload: f64,
    motors: [f64; 3],
    d12: f64,
    d22: f64,
    sag: f64,
    modes: [f64; 4],
}

const ROWS: [Row; 5] = [
    Row { payload: 0.0, motors: [0.0, 0.0, 0.0], d12: -0.01008, d22: -0.00295, sag: -0.0135, modes: [37.9, 37.9, 115.6, 115.6] },
    Row { payload: 1.0, motors: [0.0, 0.0, 0.0], d12: -0.01871, d22: -0.01847, sag: -0.0324, modes: [19.9, 19.9, 73.6, 73.7] },
    Row { payload: 2.0, motors: [0.0, 0.0, 0.0], d12: -0.02733, d22: -0.03395, sag: -0.0513, modes: [15.0, 15.0, 71.1, 71.2] },
    Row { payload: 2.0, motors: [0.0, 0.6, -0.3], d12: -0.02423, d22: -0.03302, sag: -0.0436, modes: [15.1, 15.1, 66.0, 69.9] },
    Row { payload: 2.0, motors: [0.0, FRAC_PI_2, 0.0], d12: 0.0, d22: 0.0, sag: 0.0, modes: [14.7, 14.7, 70.6, 70.6] },
];

#[test]
fn reference_table_reproduced() {
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    for row in &ROWS {
        let pd = ParamData::new(&model, &Params { payload_kg: row.payload, pressure_pa: [30e3, 30e3], flex: Flex::default() }).unwrap();
        let st = rest_state(&model, &pd, 0.0, row.motors).unwrap();
        let (d11, d12, d21, d22) = (st.q[2], st.q[3], st.q[5], st.q[6]);
        println!("payload {} motors {:?}: d11 {d11:.6} d12 {d12:.6} d21 {d21:.6} d22 {d22:.6}", row.payload, row.motors);
        assert!((d12 - row.d12).abs() < 1e-4, "d12 {d12} vs {}", row.d12);
        assert!((d22 - row.d22).abs() < 1e-4, "d22 {d22} vs {}", row.d22);
        assert!(d11.abs() < 1e-4 && d21.abs() < 1e-4);
        let mut rigid = VecN::zeros();
        for (k, &i) in model.motor_idx.iter().enumerate() {
            rigid[i] = row.motors[k];
        }
        let sag = end_effector(&model, &st.q).z - end_effector(&model, &rigid).z;
        println!("  sag {sag:.6} vs {}", row.sag);
        assert!((sag - row.sag).abs() < 5e-4, "sag {sag} vs {}", row.sag);
        let modes = popup_core::statics::locked_modes(&model, &pd, &st.q);
        println!("  modes {modes:?} vs {:?}", row.modes);
        for (m, r) in modes.iter().zip(row.modes) {
            assert!((m - r).abs() / r < 5e-3, "mode {m} vs {r}");
        }
    }
}
