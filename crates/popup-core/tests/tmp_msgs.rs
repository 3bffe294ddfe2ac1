use popup_core::control::config::parse_control;
use popup_core::model::{Model, Options};
use popup_core::spec::arm::ArmSpec;
use popup_core::scenario::Scenario;
#[test]
fn msgs() {
    let m = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    for t in ["[[phases]]\nkind = \"ready\"\nhold = true\nspeed = 3\n", "[[phases]]\nkind = \"grasping\"\n", "[[phases]]\nkind = \"moving\"\n",
              "[[obstacles]]\nname = \"ball\"\nsphere = { center = [0.0, 0.0, 1.0], radius = -0.1 }\n", "[controller]\nrate_hz = 10000.0\nbogus_gain = 1.0\n",
              "[controller.gains]\nvel_kp = [5000.0, nan, 5000.0]\n", "x = [1,\n", "[controller]\ndamping = 3\n[controller.motor]\nencoder_counts = -1\n[[controller.motors]]\ntau_max = 1\n",
              "[[obstacles]]\nname = \"a\"\nsphere = { center = [0.0, 0.0, 1.0], radius = 0.1 }\n[[obstacles]]\nname = \"a\"\nplane = { point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }\n",
              "[faults]\nwrinkle = \"explode\"\ncontact_margin = -1\n", "[[phases]]\nkind = \"ready\"\nuntil = { settled = -1 }\n[[phases]]\nname = \"x\"\n", "phases = 3\n"] {
        match parse_control(&m, t, "ctl.toml") { Ok(_) => println!("OK"), Err(e) => println!("---\n{e}") }
    }
    for t in ["duration_s = 1.0\n[effects.torsion]\nk_t = 100.0\n", "duration_s = 1.0\n[effects.backlash]\ngap = 0.01\n", "duration_s = 1.0\n[effects.payload_mass]\ndelta_kg = -5\n",
              "duration_s = 1.0\n[effects.higher_bending_modes]\nsegments = [2, 4]\n", "duration_s = 1.0\ndt = 0.5\n[controller]\nrate_hz = 2.0\n", "duration_s = 1.0\n[effects]\njoint_friction = 3\n[effects.wrinkling]\nratio = [1, 2]\nfoo = 1\n",
              "duration_s = 1.0\nseed = -1\ngravity = 1\ndescription = 3\nq0 = [0, 0, nan]\nintegrator = \"euler\"\n[log]\nchunk_size_bytes = 0\nflush_every_s = 0\nviz_rate_hz = 1000\ntopics = 3\n"] {
        match Scenario::parse(t, "s.toml", std::path::Path::new(".")) { Ok(s) => println!("OK {:?}", s.arm.effects.torsion), Err(ps) => { println!("---"); for p in ps { println!("{p}") } } }
    }
}
