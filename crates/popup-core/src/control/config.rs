//! Control files: the controller, the task sequence, the fault policy and the obstacles in
//! TOML (the `[controller]`, `[faults]`, `[[obstacles]]` and `[[phases]]` tables of a
//! scenario; the measured-run format's `[controller]` table is the same). Python's
//! `popup.control` writes exactly this format.
//!
//! ```toml
//! [controller]
//! rate_hz = 10000.0
//! damping = true                 # or [true, true, false]
//! [controller.gains]
//! vel_kp = 5000.0                # a number applies to the three joints
//! [controller.motor]             # the same motoreducer on the three joints
//! tau_max = 123.0
//!
//! [[phases]]
//! kind = "moving"                # deflated inflating ready moving grasping damping holding releasing withdrawing phase
//! track = [{ kind = "const", value = 0.0 }, { kind = "step", from = 0.0, to = 0.5, delay = 2.0 }, { kind = "const", value = 0.0 }]
//! until = { min_time = 5.0 }
//! [[phases]]
//! kind = "grasping"
//! payload_kg = 2.0
//! ```

use crate::control::collision::{Obstacle, ObstacleShape};
use crate::control::machine::{Command, FaultPolicy, Guard, Phase, Sequence};
use crate::control::reference::Signal;
use crate::control::{ControllerSpec, Gains, Motoreducer};
use crate::error::{Error, Result};
use crate::model::Model;
use serde::Deserialize;

/// A value given once for all three joints or per joint.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Three<T: Copy> {
    One(T),
    Each([T; 3]),
}

impl<T: Copy> Three<T> {
    fn get(self) -> [T; 3] {
        match self {
            Three::One(v) => [v; 3],
            Three::Each(a) => a,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct GainsToml {
    pos_kp: Option<Three<f64>>,
    pos_ki: Option<Three<f64>>,
    vel_kp: Option<Three<f64>>,
    vel_ki: Option<Three<f64>>,
    damp_kp: Option<Three<f64>>,
    damp_ki: Option<Three<f64>>,
    damp_kd: Option<Three<f64>>,
    cart_k: Option<f64>,
}

#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct MotorToml {
    gear_ratio: Option<f64>,
    torque_per_unit: Option<f64>,
    tau_max: Option<f64>,
    current_bandwidth: Option<f64>,
    encoder_counts: Option<u32>,
}

impl MotorToml {
    fn apply(&self, m: &mut Motoreducer) {
        m.gear_ratio = self.gear_ratio.unwrap_or(m.gear_ratio);
        m.torque_per_unit = self.torque_per_unit.unwrap_or(m.torque_per_unit);
        m.tau_max = self.tau_max.unwrap_or(m.tau_max);
        m.current_bandwidth = self.current_bandwidth.unwrap_or(m.current_bandwidth);
        m.encoder_counts = self.encoder_counts.unwrap_or(m.encoder_counts);
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerToml {
    rate_hz: Option<f64>,
    damping: Option<Three<bool>>,
    damping_lpf_rad_s: Option<f64>,
    v_max: Option<f64>,
    anti_windup: Option<bool>,
    #[serde(default)]
    gains: GainsToml,
    motor: Option<MotorToml>,
    motors: Option<Vec<MotorToml>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MoveToToml {
    q: [f64; 3],
    duration: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CartesianToml {
    target: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PhaseToml {
    kind: String,
    name: Option<String>,
    hold: Option<bool>,
    track: Option<[Signal; 3]>,
    velocity: Option<[Signal; 3]>,
    move_to: Option<MoveToToml>,
    cartesian: Option<CartesianToml>,
    payload_kg: Option<f64>,
    pressure_pa: Option<[f64; 2]>,
    damping: Option<Three<bool>>,
    until: Option<Guard>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereToml {
    center: [f64; 3],
    radius: f64,
}
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxToml {
    center: [f64; 3],
    half_extents: [f64; 3],
    #[serde(default)]
    yaw: f64,
}
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlaneToml {
    point: [f64; 3],
    normal: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleToml {
    name: String,
    sphere: Option<SphereToml>,
    #[serde(rename = "box")]
    cuboid: Option<BoxToml>,
    plane: Option<PlaneToml>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ControlToml {
    #[serde(default)]
    controller: ControllerToml,
    #[serde(default)]
    faults: Option<FaultPolicy>,
    #[serde(default)]
    obstacles: Vec<ObstacleToml>,
    payload_radius_m: Option<f64>,
    #[serde(default)]
    phases: Vec<PhaseToml>,
}

/// What a control file defines.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlFile {
    /// The controller.
    pub controller: ControllerSpec,
    /// The sequence (empty phases when the file has none: the caller supplies a command).
    pub sequence: Sequence,
    /// Obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Payload collision radius [m].
    pub payload_radius: f64,
}

/// The phase kinds and their defaults.
pub const PHASE_KINDS: [&str; 10] = ["deflated", "inflating", "ready", "moving", "grasping", "damping", "holding", "releasing", "withdrawing", "phase"];

fn title(kind: &str) -> String {
    let mut c = kind.chars();
    c.next().map(|f| f.to_uppercase().collect::<String>() + c.as_str()).unwrap_or_default()
}

fn build_phase(model: &Model, i: usize, p: PhaseToml) -> Result<Phase> {
    let name = p.name.clone().unwrap_or_else(|| title(&p.kind));
    let w = format!("phases[{i}] ({name})");
    if !PHASE_KINDS.contains(&p.kind.as_str()) {
        return Err(Error::input(format!("{w}.kind"), format!("unknown kind {:?}; known: {}", p.kind, PHASE_KINDS.join(", "))));
    }
    let given = [p.hold == Some(true), p.track.is_some(), p.velocity.is_some(), p.move_to.is_some(), p.cartesian.is_some()];
    if given.iter().filter(|&&g| g).count() > 1 {
        return Err(Error::input(&w, "give at most one of hold, track, velocity, move_to, cartesian"));
    }
    let command = if let Some(s) = p.track {
        Command::Track(s)
    } else if let Some(s) = p.velocity {
        Command::Velocity(s)
    } else if let Some(m) = p.move_to {
        Command::MoveTo { q: m.q, duration: m.duration }
    } else if let Some(c) = p.cartesian {
        Command::Cartesian { target: c.target }
    } else if matches!(p.kind.as_str(), "moving" | "withdrawing") {
        return Err(Error::input(&w, format!("a {} phase needs a motion: track, velocity, move_to or cartesian", p.kind)));
    } else {
        Command::Hold
    };
    let tab = &model.spec.stiffness.pressure_pa;
    let nominal = [model.spec.links[0].pressure_pa, model.spec.links[1].pressure_pa];
    let (payload_kg, pressure_pa, damping, until) = match p.kind.as_str() {
        "deflated" => (None, Some([tab[0]; 2]), None, Guard { min_time: 0.5, ..Guard::default() }),
        "inflating" => (None, Some(nominal), None, Guard { min_time: 1.0, ..Guard::default() }),
        "grasping" => {
            if p.payload_kg.is_none() {
                return Err(Error::input(&w, "a grasping phase needs payload_kg (the mass of the grasped object, kg)"));
            }
            (None, None, None, Guard { min_time: 0.2, ..Guard::default() })
        }
        "damping" => (None, None, Some([true; 3]), Guard { min_time: 0.5, max_time: 10.0, still: Some(0.05), ..Guard::default() }),
        "releasing" => (Some(0.0), None, None, Guard { min_time: 0.2, ..Guard::default() }),
        "moving" | "withdrawing" => (None, None, None, Guard { settled: Some(0.01), max_time: 30.0, ..Guard::default() }),
        _ => (None, None, None, Guard { min_time: 0.5, ..Guard::default() }),
    };
    Ok(Phase {
        name,
        command,
        payload_kg: p.payload_kg.or(payload_kg),
        pressure_pa: p.pressure_pa.or(pressure_pa),
        damping: p.damping.map(Three::get).or(damping),
        until: p.until.unwrap_or(until),
    })
}

/// Parse a control file (or the control tables of a scenario) for `model`. Unknown keys
/// are errors; `source` names the file in messages.
///
/// # Errors
/// [`Error::Input`] with the file name and the TOML parser's line/column and key, or the
/// validation errors of the controller, sequence and obstacles.
pub fn parse_control(model: &Model, text: &str, source: &str) -> Result<ControlFile> {
    let raw: ControlToml = toml::from_str(text).map_err(|e| Error::input(source, e.to_string()))?;
    let mut c = ControllerSpec::default();
    let ct = raw.controller;
    c.rate_hz = ct.rate_hz.unwrap_or(c.rate_hz);
    c.damping = ct.damping.map(Three::get).unwrap_or(c.damping);
    c.damping_lpf = ct.damping_lpf_rad_s.unwrap_or(c.damping_lpf);
    c.v_max = ct.v_max.unwrap_or(c.v_max);
    c.anti_windup = ct.anti_windup.unwrap_or(c.anti_windup);
    let gt = ct.gains;
    let d = Gains::default();
    c.gains = Gains {
        pos_kp: gt.pos_kp.map_or(d.pos_kp, Three::get),
        pos_ki: gt.pos_ki.map_or(d.pos_ki, Three::get),
        vel_kp: gt.vel_kp.map_or(d.vel_kp, Three::get),
        vel_ki: gt.vel_ki.map_or(d.vel_ki, Three::get),
        damp_kp: gt.damp_kp.map_or(d.damp_kp, Three::get),
        damp_ki: gt.damp_ki.map_or(d.damp_ki, Three::get),
        damp_kd: gt.damp_kd.map_or(d.damp_kd, Three::get),
        cart_k: gt.cart_k.unwrap_or(d.cart_k),
    };
    if ct.motor.is_some() && ct.motors.is_some() {
        return Err(Error::input(format!("{source}: controller"), "give either [controller.motor] (all joints) or [[controller.motors]] (three), not both"));
    }
    if let Some(m) = ct.motor {
        for mm in c.motors.iter_mut() {
            m.apply(mm);
        }
    }
    if let Some(ms) = ct.motors {
        if ms.len() != 3 {
            return Err(Error::input(format!("{source}: controller.motors"), format!("needs 3 entries (q1, q2, q3), got {}", ms.len())));
        }
        for (mm, m) in c.motors.iter_mut().zip(ms) {
            m.apply(mm);
        }
    }
    c.validate()?;
    let phases = raw.phases.into_iter().enumerate().map(|(i, p)| build_phase(model, i, p)).collect::<Result<Vec<_>>>()?;
    let sequence = Sequence { phases, faults: raw.faults.unwrap_or_default() };
    if !sequence.phases.is_empty() {
        sequence.validate()?;
    }
    let mut obstacles = Vec::new();
    for (i, o) in raw.obstacles.into_iter().enumerate() {
        let shapes = [o.sphere.is_some(), o.cuboid.is_some(), o.plane.is_some()].iter().filter(|&&b| b).count();
        if shapes != 1 {
            return Err(Error::input(format!("obstacles[{i}] ({})", o.name), "needs exactly one of sphere, box, plane"));
        }
        let shape = if let Some(s) = o.sphere {
            ObstacleShape::Sphere { center: s.center, radius: s.radius }
        } else if let Some(b) = o.cuboid {
            ObstacleShape::Box { center: b.center, half_extents: b.half_extents, yaw: b.yaw }
        } else {
            let p = o.plane.expect("counted above");
            ObstacleShape::Plane { point: p.point, normal: p.normal }
        };
        obstacles.push(Obstacle { name: o.name, shape });
    }
    crate::control::collision::CollisionWorld::new(&obstacles)?;
    Ok(ControlFile { controller: c, sequence, obstacles, payload_radius: raw.payload_radius_m.unwrap_or(0.05) })
}
