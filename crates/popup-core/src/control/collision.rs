//! Collision awareness: the arm's links and payload as capsules/spheres against
//! user-declared obstacles, with parry3d-f64 distance queries. Frames: everything in the
//! base frame W, metres.
//!
//! A capsule with `a != b` is queried as its core segment against the obstacle and the
//! radius is subtracted afterwards (exact, no iterative rounding of the capsule); a capsule
//! with `a == b` is queried as a ball. When the core segment enters a box, or comes within
//! ~1e-6 of its size, the signed distance is computed here (closed form / 1-D convex search):
//! parry's GJK cannot certify such tiny gaps and would fall back to EPA, which allocates.
//! No query allocates.

use crate::error::{Error, Result};
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::{Ball, Cuboid, HalfSpace, Segment, Shape};

/// Shape of an obstacle, in the base frame W [m].
#[derive(Debug, Clone, PartialEq)]
pub enum ObstacleShape {
    /// Sphere: centre p_WC [m], radius [m].
    Sphere {
        /// Centre in W [m].
        center: [f64; 3],
        /// Radius [m], > 0.
        radius: f64,
    },
    /// Box given by its centre and half extents, rotated by `yaw` about W's z axis [rad]
    /// (axis-aligned in W when `yaw == 0`).
    Box {
        /// Centre in W [m].
        center: [f64; 3],
        /// Half extents along the box axes [m], each > 0.
        half_extents: [f64; 3],
        /// Rotation about W's z axis [rad].
        yaw: f64,
    },
    /// Half-space below a plane (e.g. a table top): points p with (p − point)·normal < 0 are
    /// inside. `normal` need not be unit (normalised on construction) but must be non-zero.
    Plane {
        /// A point on the plane, in W [m].
        point: [f64; 3],
        /// Outward normal (any non-zero length) in W.
        normal: [f64; 3],
    },
}

/// A named obstacle.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// Unique, non-empty name.
    pub name: String,
    /// Geometry in W [m].
    pub shape: ObstacleShape,
}

/// A moving part of the arm: a capsule between two points in W with a radius (a link tube;
/// a sphere when a == b, e.g. the payload).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    /// First end of the core segment, in W [m].
    pub a: [f64; 3],
    /// Second end of the core segment, in W [m].
    pub b: [f64; 3],
    /// Radius [m], > 0.
    pub radius: f64,
}

/// The closest pair found by a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Closest {
    /// Index of the arm part (capsule) in the slice passed to `distances`.
    pub part: usize,
    /// Index of the obstacle.
    pub obstacle: usize,
    /// Signed distance [m]: > 0 separated, < 0 penetration depth.
    pub distance: f64,
    /// Witness point on the arm part, in W [m] (the deepest point when penetrating).
    pub point_arm: [f64; 3],
    /// Witness point on the obstacle surface, in W [m].
    pub point_obstacle: [f64; 3],
}

/// One pair result: signed distance [m], witness on the arm and on the obstacle (W) [m].
struct Hit { dist: f64, arm: Vector, obs: Vector }

/// Obstacles compiled to parry shapes once (immutable during a run).
pub struct CollisionWorld {
    names: Vec<String>,
    shapes: Vec<Box<dyn Shape>>,
    poses: Vec<Pose>,
}

impl std::fmt::Debug for CollisionWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollisionWorld").field("names", &self.names).finish_non_exhaustive()
    }
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl CollisionWorld {
    /// Validate and compile. Errors (`Error::input` with what = "obstacles[i] (name)") for:
    /// non-finite numbers, radius <= 0, half extents <= 0, zero normal, empty or duplicate
    /// names.
    pub fn new(obstacles: &[Obstacle]) -> Result<CollisionWorld> {
        let n = obstacles.len();
        let (mut names, mut shapes, mut poses) =
            (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        for (i, o) in obstacles.iter().enumerate() {
            let what = format!("obstacles[{i}] ({})", o.name);
            let bad = |detail: String| Err(Error::input(what.clone(), detail));
            if o.name.is_empty() {
                return bad("the name must not be empty".into());
            }
            if let Some(j) = obstacles[..i].iter().position(|p| p.name == o.name) {
                return bad(format!("duplicate name {:?} (also obstacles[{j}])", o.name));
            }
            let (shape, pose): (Box<dyn Shape>, Pose) = match &o.shape {
                ObstacleShape::Sphere { center, radius } => {
                    if !(finite3(center) && radius.is_finite() && *radius > 0.0) {
                        return bad(format!("sphere center {center:?} must be finite, radius {radius} m finite and > 0"));
                    }
                    (Box::new(Ball::new(*radius)), Pose::from_translation(Vector::from_array(*center)))
                }
                ObstacleShape::Box { center, half_extents, yaw } => {
                    if !finite3(center) || !finite3(half_extents) || !yaw.is_finite() || half_extents.iter().any(|&h| h <= 0.0) {
                        return bad(format!("box center {center:?}, yaw {yaw} must be finite, half_extents {half_extents:?} m finite and > 0"));
                    }
                    let rot = Rotation::from_rotation_z(*yaw);
                    let pose = Pose::from_parts(Vector::from_array(*center), rot);
                    (Box::new(Cuboid::new(Vector::from_array(*half_extents))), pose)
                }
                ObstacleShape::Plane { point, normal } => {
                    let (nv, len) = Vector::from_array(*normal).normalize_and_length();
                    if !(finite3(point) && finite3(normal) && len > 0.0 && len.is_finite()) {
                        return bad(format!("plane point {point:?} must be finite, normal {normal:?} finite and non-zero"));
                    }
                    (Box::new(HalfSpace::new(nv)), Pose::from_translation(Vector::from_array(*point)))
                }
            };
            names.push(o.name.clone());
            shapes.push(shape);
            poses.push(pose);
        }
        Ok(CollisionWorld { names, shapes, poses })
    }

    /// Number of obstacles.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True when there are no obstacles.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Obstacle names in order.
    pub fn names(&self) -> Vec<&str> {
        self.names.iter().map(String::as_str).collect()
    }

    /// For each part, the signed minimum distance [m] to any obstacle into `out[part]`
    /// (+inf when there are no obstacles), and the overall closest pair (None when there are
    /// no obstacles). Does not allocate on success. Errors: `out.len() != parts.len()`, a
    /// part with radius <= 0 or non-finite numbers (`Error::input("collision part i", ..)`).
    pub fn distances(&self, parts: &[Capsule], out: &mut [f64]) -> Result<Option<Closest>> {
        if out.len() != parts.len() {
            return Err(Error::input(
                "collision distances out",
                format!("length {} must equal the number of parts {}", out.len(), parts.len()),
            ));
        }
        for (i, p) in parts.iter().enumerate() {
            if !finite3(&p.a) || !finite3(&p.b) || !p.radius.is_finite() || p.radius <= 0.0 {
                return Err(Error::input(
                    format!("collision part {i}"),
                    format!("a = {:?}, b = {:?} must be finite and radius = {} m > 0", p.a, p.b, p.radius),
                ));
            }
        }
        let mut closest: Option<Closest> = None;
        for (i, p) in parts.iter().enumerate() {
            let (a, b) = (Vector::from_array(p.a), Vector::from_array(p.b));
            let mut best = f64::INFINITY;
            for k in 0..self.shapes.len() {
                let h = self.pair(k, a, b, p.radius).ok_or_else(|| {
                    Error::input(
                        format!("collision part {i}"),
                        format!("parry query against obstacles[{k}] ({}) failed", self.names[k]),
                    )
                })?;
                best = best.min(h.dist);
                if !matches!(closest, Some(c) if c.distance <= h.dist) {
                    let (distance, point_arm, point_obstacle) = (h.dist, h.arm.to_array(), h.obs.to_array());
                    closest = Some(Closest { part: i, obstacle: k, distance, point_arm, point_obstacle });
                }
            }
            out[i] = best;
        }
        Ok(closest)
    }

    /// Signed distance and witnesses between capsule (a, b, r) and obstacle k.
    fn pair(&self, k: usize, a: Vector, b: Vector, r: f64) -> Option<Hit> {
        let (pose, shape) = (&self.poses[k], &*self.shapes[k]);
        // Obstacle first, then flipped: parry 0.31.1's `contact_support_map_halfspace`
        // (part first, half-space second) forgets to invert pos12 and returns wrong results.
        if a == b {
            let c = query::contact(pose, shape, &Pose::from_translation(a), &Ball::new(r), f64::INFINITY)
                .ok()??
                .flipped();
            return Some(Hit { dist: c.dist, arm: c.point1, obs: c.point2 });
        }
        if let Some(cub) = shape.as_cuboid() {
            if let Some(h) = segment_touching_box(pose, cub.half_extents, a, b, r) {
                return Some(h);
            }
        }
        let c = query::contact(pose, shape, &Pose::IDENTITY, &Segment::new(a, b), f64::INFINITY).ok()??.flipped();
        Some(Hit { dist: c.dist - r, arm: c.point1 + c.normal1 * r, obs: c.point2 })
    }
}

/// Closed-form signed distance of a capsule whose core segment touches or enters a box
/// (None when the core is clearly outside: parry's GJK then handles it exactly).
///
/// In the box frame, g(p) = max_i(|p_i| − h_i) is a lower bound on the signed distance,
/// equal to it inside the box. Along the segment g is convex piecewise linear, so its
/// minimum lies at an end or a breakpoint (|p_i| kinks and crossings of ±p_i − h_i).
fn segment_touching_box(pose: &Pose, h: Vector, a: Vector, b: Vector, r: f64) -> Option<Hit> {
    let (pa, pb) = (pose.inverse_transform_point(a), pose.inverse_transform_point(b));
    let d = pb - pa;
    let at = |t: f64| pa + d * t;
    let g = |p: Vector| (p.abs() - h).max_element();
    let (mut cand, mut n) = ([0.0; 17], 2); // t = 0, 1, then 15 breakpoints
    cand[1] = 1.0;
    for i in 0..3 {
        cand[n] = -pa[i] / d[i];
        n += 1;
        for j in (i + 1)..3 {
            for (si, sj) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                cand[n] = (h[i] - h[j] - si * pa[i] + sj * pa[j]) / (si * d[i] - sj * d[j]);
                n += 1;
            }
        }
    }
    let (mut t_best, mut g_best) = (0.0, f64::INFINITY);
    for &t in &cand {
        if t.is_finite() {
            let t = t.clamp(0.0, 1.0);
            let gt = g(at(t));
            if gt < g_best {
                (t_best, g_best) = (t, gt);
            }
        }
    }
    // GJK cannot certify separations below ~5e-8 of the shapes' size (it would fall back to
    // EPA): handle that band here too.
    let tol = 1e-6 * (1.0 + h.length() + pa.length().max(pb.length()));
    if g_best > tol {
        return None;
    }
    if g_best > 0.0 {
        // Core just outside: the Euclidean distance is convex along the segment; ternary
        // search to round-off (100 steps shrink the interval by 2.5e-18).
        let f = |t: f64| at(t).distance_squared(at(t).clamp(-h, h));
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..100 {
            let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
            if f(m1) <= f(m2) { hi = m2 } else { lo = m1 }
        }
        let p = at(0.5 * (lo + hi));
        let s = p.clamp(-h, h);
        let (dir, len) = (s - p).normalize_and_length();
        let arm = pose.transform_point(p + dir * r);
        return Some(Hit { dist: len - r, arm, obs: pose.transform_point(s) });
    }
    // Core inside: the deepest point and its nearest face (outward normal n_f).
    let p = at(t_best);
    let axis = (p.abs() - h).max_position();
    let mut n_f = Vector::ZERO;
    n_f[axis] = if p[axis] >= 0.0 { 1.0 } else { -1.0 };
    let mut s = p;
    s[axis] = n_f[axis] * h[axis];
    Some(Hit { dist: g_best - r, arm: pose.transform_point(p - n_f * r), obs: pose.transform_point(s) })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] { [a[0] - b[0], a[1] - b[1], a[2] - b[2]] }
    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 { a[0] * b[0] + a[1] * b[1] + a[2] * b[2] }
    fn norm(a: [f64; 3]) -> f64 { dot(a, a).sqrt() }
    fn seg_dist(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
        let (ab, ap) = (sub(b, a), sub(p, a));
        let t = if dot(ab, ab) > 0.0 { (dot(ap, ab) / dot(ab, ab)).clamp(0.0, 1.0) } else { 0.0 };
        norm(sub(ap, [ab[0] * t, ab[1] * t, ab[2] * t]))
    }
    fn obs(name: &str, shape: ObstacleShape) -> Obstacle { Obstacle { name: name.into(), shape } }
    fn one(w: &CollisionWorld, c: Capsule) -> Closest {
        let mut out = [0.0];
        let cl = w.distances(&[c], &mut out).unwrap().unwrap();
        assert_eq!(out[0], cl.distance);
        cl
    }
    /// Reference signed distance from a point to a box (centre c, half extents h, yaw).
    fn box_sdf(p: [f64; 3], c: [f64; 3], h: [f64; 3], yaw: f64) -> f64 {
        let (s, co) = yaw.sin_cos();
        let v = sub(p, c);
        let l = [co * v[0] + s * v[1], -s * v[0] + co * v[1], v[2]];
        let q = [l[0].abs() - h[0], l[1].abs() - h[1], l[2].abs() - h[2]];
        norm([q[0].max(0.0), q[1].max(0.0), q[2].max(0.0)]) + q[0].max(q[1]).max(q[2]).min(0.0)
    }
    /// Reference capsule–box distance: ternary search of the convex sdf along the segment.
    fn capsule_box_ref(cap: Capsule, c: [f64; 3], h: [f64; 3], yaw: f64) -> f64 {
        let f = |t: f64| box_sdf([0, 1, 2].map(|i| cap.a[i] + t * (cap.b[i] - cap.a[i])), c, h, yaw);
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..200 {
            let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
            if f(m1) <= f(m2) { hi = m2 } else { lo = m1 }
        }
        f(0.5 * (lo + hi)) - cap.radius
    }

    #[test]
    fn sphere_capsule_closed_form() {
        let (c, rs) = ([0.3, -0.2, 0.5], 0.1);
        let w = CollisionWorld::new(&[obs("ball", ObstacleShape::Sphere { center: c, radius: rs })]).unwrap();
        let caps = [
            Capsule { a: [0.0, 0.0, 0.0], b: [0.0, 0.0, 1.0], radius: 0.05 }, // interior projection
            Capsule { a: [1.0, 1.0, 1.0], b: [2.0, 1.5, 0.0], radius: 0.02 }, // endpoint closest
            Capsule { a: [0.25, -0.2, 0.0], b: [0.25, -0.2, 1.0], radius: 0.03 }, // penetrating
            Capsule { a: [0.3, -0.2, 0.0], b: [0.3, -0.2, 1.0], radius: 0.03 }, // centre on the core
            Capsule { a: [0.6, 0.1, 0.9], b: [0.6, 0.1, 0.9], radius: 0.04 }, // ball part
        ];
        for cap in caps {
            let cl = one(&w, cap);
            let expect = seg_dist(c, cap.a, cap.b) - rs - cap.radius;
            assert!((cl.distance - expect).abs() < 1e-9, "{cap:?}: {} vs {expect}", cl.distance);
            assert!((norm(sub(cl.point_obstacle, c)) - rs).abs() < 1e-9);
            assert!((norm(sub(cl.point_obstacle, cl.point_arm)) - cl.distance.abs()).abs() < 1e-9);
        }
    }

    #[test]
    fn capsule_and_planes() {
        let table = obs("table", ObstacleShape::Plane { point: [0.0, 0.0, 0.7], normal: [0.0, 0.0, 3.0] });
        let w = CollisionWorld::new(&[table]).unwrap();
        let cap = Capsule { a: [0.1, 0.2, 1.0], b: [0.5, 0.0, 0.8], radius: 0.05 };
        let cl = one(&w, cap);
        assert!((cl.distance - (0.8 - 0.7 - 0.05)).abs() < 1e-12);
        assert!((seg_dist(cl.point_arm, cap.a, cap.b) - 0.05).abs() < 1e-12);
        assert!((cl.point_obstacle[2] - 0.7).abs() < 1e-12);
        // penetrating the table: −depth
        let cap2 = Capsule { a: [0.0, 0.0, 0.9], b: [0.3, 0.0, 0.68], radius: 0.05 };
        assert!((one(&w, cap2).distance - (0.68 - 0.7 - 0.05)).abs() < 1e-12);
        // tilted, non-unit normal
        let (pt, n) = ([0.0, 0.0, 0.1], [1.0, 0.0, 1.0]);
        let w = CollisionWorld::new(&[obs("ramp", ObstacleShape::Plane { point: pt, normal: n })]).unwrap();
        let cap3 = Capsule { a: [0.0, 0.0, 1.0], b: [1.0, 0.0, 2.0], radius: 0.05 };
        let h = |p: [f64; 3]| dot(sub(p, pt), n) / norm(n);
        let cl = one(&w, cap3);
        assert!((cl.distance - (h(cap3.a).min(h(cap3.b)) - 0.05)).abs() < 1e-12);
        assert!(h(cl.point_obstacle).abs() < 1e-12);
    }

    #[test]
    fn boxes() {
        let (c, h) = ([1.0, 0.0, 0.5], [0.2, 0.3, 0.4]);
        let w = CollisionWorld::new(&[obs("crate", ObstacleShape::Box { center: c, half_extents: h, yaw: 0.0 })])
            .unwrap();
        // parallel to the +x face at gap 0.1
        let r = 0.05;
        let cap = Capsule { a: [1.2 + 0.1 + r, -0.1, 0.3], b: [1.2 + 0.1 + r, 0.1, 0.6], radius: r };
        let cl = one(&w, cap);
        assert!((cl.distance - 0.1).abs() < 1e-9, "{}", cl.distance);
        assert!((cl.point_obstacle[0] - 1.2).abs() < 1e-9 && (cl.point_arm[0] - 1.3).abs() < 1e-9);
        // core inside the box (closed form) and capsule-only penetration (GJK)
        let deep = Capsule { a: [0.9, 0.0, 0.7], b: [1.1, 0.0, 0.7], radius: r };
        assert!((one(&w, deep).distance - (-0.2 - r)).abs() < 1e-12);
        let skim = Capsule { a: [0.9, 0.0, 0.93], b: [1.1, 0.0, 0.93], radius: r };
        assert!((one(&w, skim).distance - (0.03 - r)).abs() < 1e-9);
        // core 1e-8 above the top face (the band GJK cannot certify) and touching it
        for gap in [1e-8, 0.0] {
            let near = Capsule { a: [0.9, -0.1, 0.9 + gap], b: [1.3, 0.2, 0.9 + gap], radius: r };
            assert!((one(&w, near).distance - (gap - r)).abs() < 1e-15);
        }
        let e = 1e-8 * std::f64::consts::FRAC_1_SQRT_2; // 1e-8 off the top +x edge, diagonally
        let edge = Capsule { a: [1.2 + e, -0.1, 0.9 + e], b: [1.2 + e, 0.2, 0.9 + e], radius: r };
        assert!((one(&w, edge).distance - (1e-8 - r)).abs() < 1e-15);
        // yawed box, point-like part near a corner
        let (c, h, yaw) = ([0.2, -0.1, 0.0], [0.5, 0.25, 0.3], std::f64::consts::FRAC_PI_4);
        let w = CollisionWorld::new(&[obs("yawed", ObstacleShape::Box { center: c, half_extents: h, yaw })])
            .unwrap();
        let (s, co) = yaw.sin_cos();
        let l = [0.6, 0.4, 0.35];
        let p = [c[0] + co * l[0] - s * l[1], c[1] + s * l[0] + co * l[1], c[2] + l[2]];
        let cl = one(&w, Capsule { a: p, b: p, radius: 0.02 });
        let expect = norm([0.1, 0.15, 0.05]) - 0.02;
        assert!((cl.distance - expect).abs() < 1e-9 && (box_sdf(p, c, h, yaw) - 0.02 - expect).abs() < 1e-12);
        // segments against the yawed box: separated, skimming, core crossing it
        for cap in [
            Capsule { a: [1.0, 0.5, 0.1], b: [0.3, 1.2, 0.5], radius: 0.03 },
            Capsule { a: [-1.0, 0.3, 0.2], b: [0.9, 0.6, -0.4], radius: 0.1 },
            Capsule { a: [-0.5, -0.8, 0.1], b: [0.9, 0.7, 0.2], radius: 0.04 },
            Capsule { a: [0.2, -0.1, 0.25], b: [0.21, -0.1, 0.9], radius: 0.04 },
        ] {
            let cl = one(&w, cap);
            let expect = capsule_box_ref(cap, c, h, yaw);
            assert!((cl.distance - expect).abs() < 1e-9, "{cap:?}: {} vs {expect}", cl.distance);
            assert!(box_sdf(cl.point_obstacle, c, h, yaw).abs() < 1e-9);
            assert!((norm(sub(cl.point_obstacle, cl.point_arm)) - cl.distance.abs()).abs() < 1e-9);
        }
    }

    #[test]
    fn closest_pair_among_several_and_determinism() {
        let w = CollisionWorld::new(&[
            obs("table", ObstacleShape::Plane { point: [0.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0] }),
            obs("ball", ObstacleShape::Sphere { center: [0.5, 0.5, 0.5], radius: 0.1 }),
            obs("crate", ObstacleShape::Box { center: [-1.5, 0.0, 0.3], half_extents: [0.1; 3], yaw: 0.3 }),
        ])
        .unwrap();
        assert_eq!((w.len(), w.is_empty(), w.names()), (3, false, vec!["table", "ball", "crate"]));
        fn send_sync<T: Send + Sync>(_: &T) {}
        send_sync(&w);
        assert!(format!("{w:?}").contains("crate"));
        let parts = [
            Capsule { a: [0.0, 0.0, 0.6], b: [0.0, 0.0, 1.0], radius: 0.05 }, // table 0.55
            Capsule { a: [0.2, 0.5, 0.7], b: [0.8, 0.5, 0.7], radius: 0.05 }, // ball 0.2-0.15
            Capsule { a: [0.0, 0.0, 1.0], b: [0.0, 0.0, 1.0], radius: 0.08 }, // payload
        ];
        let mut out = [0.0; 3];
        let cl = w.distances(&parts, &mut out).unwrap().unwrap();
        assert_eq!((cl.part, cl.obstacle), (1, 1));
        assert!((cl.distance - 0.05).abs() < 1e-12 && (out[1] - 0.05).abs() < 1e-12);
        assert!((out[0] - 0.55).abs() < 1e-12 && (out[2] - (0.75f64.sqrt() - 0.18)).abs() < 1e-12);
        assert!((seg_dist(cl.point_arm, parts[1].a, parts[1].b) - 0.05).abs() < 1e-9);
        assert!((norm(sub(cl.point_obstacle, [0.5, 0.5, 0.5])) - 0.1).abs() < 1e-9);
        let mut out2 = [0.0; 3];
        let cl2 = w.distances(&parts, &mut out2).unwrap().unwrap();
        assert_eq!(out.map(f64::to_bits), out2.map(f64::to_bits));
        assert_eq!(cl.point_arm.map(f64::to_bits), cl2.point_arm.map(f64::to_bits));
        assert_eq!(cl.point_obstacle.map(f64::to_bits), cl2.point_obstacle.map(f64::to_bits));
        assert_eq!(cl.distance.to_bits(), cl2.distance.to_bits());
    }

    #[test]
    fn empty_world_and_validation() {
        let w = CollisionWorld::new(&[]).unwrap();
        let mut out = [0.0; 2];
        let cap = Capsule { a: [0.0; 3], b: [0.0, 0.0, 1.0], radius: 0.1 };
        assert_eq!(w.distances(&[cap, cap], &mut out).unwrap(), None);
        assert_eq!(out, [f64::INFINITY; 2]);
        let sphere = |r: f64| ObstacleShape::Sphere { center: [0.0; 3], radius: r };
        let err = |o: Vec<Obstacle>| CollisionWorld::new(&o).unwrap_err().to_string();
        let e = err(vec![obs("a", sphere(1.0)), obs("b", sphere(0.0))]);
        assert!(e.contains("obstacles[1] (b)") && e.contains("radius"), "{e}");
        let e = err(vec![obs("c", ObstacleShape::Sphere { center: [f64::NAN, 0.0, 0.0], radius: 1.0 })]);
        assert!(e.contains("obstacles[0] (c)") && e.contains("NaN"), "{e}");
        let e = err(vec![obs("a", sphere(1.0)), obs("t", ObstacleShape::Plane { point: [0.0; 3], normal: [0.0; 3] })]);
        assert!(e.contains("obstacles[1] (t)") && e.contains("non-zero"), "{e}");
        let e = err(vec![obs("a", sphere(1.0)), obs("x", sphere(1.0)), obs("a", sphere(2.0))]);
        assert!(e.contains("obstacles[2] (a)") && e.contains("duplicate"), "{e}");
        let e = err(vec![obs("", sphere(1.0))]);
        assert!(e.contains("obstacles[0] ()") && e.contains("empty"), "{e}");
        let bx = ObstacleShape::Box { center: [0.0; 3], half_extents: [0.1, 0.0, 0.1], yaw: 0.0 };
        assert!(err(vec![obs("b", bx)]).contains("half_extents"));
        let w = CollisionWorld::new(&[obs("a", sphere(1.0))]).unwrap();
        let nan = Capsule { a: [0.0, f64::NAN, 0.0], ..cap };
        let e = w.distances(&[cap, nan], &mut out).unwrap_err().to_string();
        assert!(e.contains("collision part 1"), "{e}");
        let thin = Capsule { radius: 0.0, ..cap };
        assert!(w.distances(&[thin], &mut out[..1]).unwrap_err().to_string().contains("collision part 0"));
    }
}
