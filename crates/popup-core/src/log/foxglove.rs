//! Foxglove well-known messages (JSON): body frames, the arm as cylinders, log lines.

use crate::kinematics::prbm::Frames;
use crate::math::{Mat3, Vec3};
use nalgebra::{Rotation3, UnitQuaternion};
use serde_json::{json, Value};

/// Official schema texts (vendored, `schemas/README.md`).
pub const FRAME_TRANSFORMS: &str = include_str!("schemas/foxglove.FrameTransforms.json");
/// `foxglove.SceneUpdate` schema.
pub const SCENE_UPDATE: &str = include_str!("schemas/foxglove.SceneUpdate.json");
/// `foxglove.Log` schema.
pub const LOG: &str = include_str!("schemas/foxglove.Log.json");

/// Log levels of `foxglove.Log`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// 2
    Info = 2,
    /// 3
    Warning = 3,
    /// 4
    Error = 4,
}

/// `{sec, nsec}` of a time in integer nanoseconds.
pub fn time(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn vec3(v: &Vec3) -> Value {
    json!({"x": v.x, "y": v.y, "z": v.z})
}

fn quat(r: &Mat3) -> Value {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    json!({"x": q.i, "y": q.j, "z": q.k, "w": q.w})
}

/// `foxglove.FrameTransforms`: `world` → each named frame (`names[i]` is frame `i` of
/// `fr`), plus `ee` at `p_ee` with the orientation of frame `ee_frame`.
pub fn frame_transforms(ns: u64, fr: &Frames, names: &[String], ee_frame: usize, p_ee: &Vec3) -> Value {
    let ts = time(ns);
    let mut tf: Vec<Value> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            json!({"timestamp": ts, "parent_frame_id": "world", "child_frame_id": n, "translation": vec3(&fr.p_wb[i]), "rotation": quat(&fr.r_wb[i])})
        })
        .collect();
    tf.push(json!({"timestamp": ts, "parent_frame_id": "world", "child_frame_id": "ee", "translation": vec3(p_ee), "rotation": quat(&fr.r_wb[ee_frame])}));
    json!({ "transforms": tf })
}

/// Colour of a link at |M|/M_w = `r`: green (0) → yellow (0.5) → red (≥ 1).
pub fn ratio_color(r: f64) -> Value {
    let x = if r.is_finite() { r.clamp(0.0, 1.0) } else { 1.0 };
    let (red, green) = if x < 0.5 { (2.0 * x, 1.0) } else { (1.0, 2.0 * (1.0 - x)) };
    json!({"r": red, "g": green, "b": 0.1, "a": 1.0})
}

fn entity(ts: &Value, id: &str, cylinders: Vec<Value>, spheres: Vec<Value>, meta: Vec<Value>) -> Value {
    json!({
        "timestamp": ts, "frame_id": "world", "id": id, "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": false,
        "metadata": meta, "arrows": [], "cubes": [], "spheres": spheres, "cylinders": cylinders,
        "lines": [], "triangles": [], "texts": [], "models": [],
    })
}

/// A cylinder from `a` to `b` [m] of radius `r` [m].
pub fn cylinder(a: &Vec3, b: &Vec3, r: f64, color: Value) -> Value {
    let d = b - a;
    let len = d.norm();
    let rot = UnitQuaternion::rotation_between(&Vec3::z(), &d).unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vec3::x_axis(), std::f64::consts::PI));
    let c = (a + b) * 0.5;
    json!({
        "pose": {"position": vec3(&c), "orientation": {"x": rot.i, "y": rot.j, "z": rot.k, "w": rot.w}},
        "size": {"x": 2.0 * r, "y": 2.0 * r, "z": len}, "bottom_scale": 1.0, "top_scale": 1.0, "color": color,
    })
}

/// `foxglove.SceneUpdate` with one entity per link (`links[l]` its cylinders, `ratio[l]`
/// its |M|/M_w) and the payload sphere (centre, radius) if any.
pub fn scene(ns: u64, links: [Vec<Value>; 2], ratio: [f64; 2], payload: Option<(Vec3, f64, f64)>) -> Value {
    let ts = time(ns);
    let mut ents: Vec<Value> = Vec::new();
    for (l, cyl) in links.into_iter().enumerate() {
        let meta = vec![json!({"key": "M/M_w", "value": format!("{:.3}", ratio[l])})];
        ents.push(entity(&ts, &format!("link{}", l + 1), cyl, vec![], meta));
    }
    if let Some((c, r, m)) = payload {
        let s = json!({"pose": {"position": vec3(&c), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}, "size": {"x": 2.0 * r, "y": 2.0 * r, "z": 2.0 * r}, "color": {"r": 0.6, "g": 0.6, "b": 0.6, "a": 1.0}});
        ents.push(entity(&ts, "payload", vec![], vec![s], vec![json!({"key": "mass_kg", "value": format!("{m}")})]));
    }
    json!({"deletions": [], "entities": ents})
}

/// `foxglove.Log`.
pub fn log(ns: u64, level: Level, name: &str, message: &str) -> Value {
    json!({"timestamp": time(ns), "level": level as u8, "message": message, "name": name, "file": "", "line": 0})
}
