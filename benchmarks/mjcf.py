"""An MJCF (MuJoCo) model of a popup arm's 7-DOF pseudo-rigid-body chain.

The model is built from the arm description itself (``model.arm.to_toml()``: DH rows,
bodies and their mass parts, link radii, stiffness table, armature, payload mount,
gravity), not from popup's derived quantities, so that comparing MuJoCo with popup checks
popup's kinematics and dynamics against an independent engine:

* Frames. Standard DH, ``A_i = Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)`` with
  ``θ_i = q_i + theta_offset_i``. With ``G_i = Rz(offset_i) Tz(d_i) Tx(a_i) Rx(α_i)``
  (fixed) we have ``T_i = T_{i-1} Rz(q_i) G_i = T_{i-1} G_i (G_i⁻¹ Rz(q_i) G_i)``, and
  ``G⁻¹ Rz(q) G`` is a rotation by q about the axis ``R_G^T e_z`` through the point
  ``-R_G^T p_G``. So MuJoCo body i is nested in body i-1 with ``pos = p_G``,
  ``quat = R_G`` and a hinge with ``axis = R_G^T e_z``, ``pos = -R_G^T p_G`` (both in
  body i's own frame): the MuJoCo body frame then *is* DH frame i for every q (checked
  against ``popup.Model.frames`` by ``check_against_popup``).
* Inertia. Body i carries the sum of its parts (point masses with their extra inertia;
  thin-walled tubes along local x: I_xx = m r², I_yy = I_zz = m (r²/2 + l²/12) about the
  centre, r = the link's radius unless the part gives one), plus the payload on its body,
  combined into one ``<inertial>`` (mass, centre, full inertia about the centre) with the
  parallel-axis theorem.
* Massless bodies (the gimbals between the two bending joints of a link, bodies 3 and 6)
  get ``mass = MASSLESS_KG`` (1e-14 kg) and a diagonal inertia ``MASSLESS_INERTIA``
  (1e-14 kg·m²) at their origin, because MuJoCo's compiler rejects a moving body whose
  mass or inertia is below mjMINVAL = 1e-15 ("mass and inertia of moving bodies must be
  larger than mjMINVAL"). Effect: about 3e-14 relative on the mass matrix and on gravity.
  The popup/MuJoCo difference scales with this dummy mass (1e-9 kg gave 4e-10, 1e-12 kg
  gave 4e-13), i.e. it is this dummy mass and nothing else.
* Joints. Bending joints get ``stiffness`` (k) and ``damping`` (c) from the arm's Table-3
  values interpolated linearly at the link pressure and scaled by (r/r_ref)³ unless the
  link gives ``stiffness_scale`` (computed here, not taken from popup); springref = 0.
  Motor joints get ``armature`` from ``motors.armature_kgm2`` and a ``<motor>`` actuator
  (gear 1, no control limits), so ``ctrl`` is the motor torque at the joint [N·m].
* Options: ``gravity`` from the arm, ``timestep = dt``, the requested integrator
  (``implicitfast`` by default), contacts/constraints not present (no geoms).
"""

from __future__ import annotations

import tomllib
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

MASSLESS_KG = 1e-14
MASSLESS_INERTIA = 1e-14


# ----------------------------------------------------------------------------- small math
def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _mat2quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(r)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def _f(x: float) -> str:
    """Full-precision float for MJCF (repr round-trips exactly)."""
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def _fs(v: Sequence[float]) -> str:
    return " ".join(_f(x) for x in v)


# ----------------------------------------------------------------------------- arm data
def _interp_clamped(xs: Sequence[float], ys: Sequence[float], x: float) -> float:
    return float(np.interp(x, xs, ys))  # np.interp clamps to the end values


def arm_data(model: Any) -> Dict[str, Any]:
    """Numbers of ``model`` (a ``popup.Model``) read from its arm file, plus the payload
    and pressures of the model. Stiffness and damping are computed here from the table."""
    d = tomllib.loads(model.arm.to_toml())
    links = d["links"]
    st = d["stiffness"]
    kl, cl = [], []
    for li, link in enumerate(links):
        scale = link.get("stiffness_scale")
        if scale is None:
            scale = (link["radius_m"] / st["reference_radius_m"]) ** 3
        p = model.pressure_pa[li]
        kl.append(scale * _interp_clamped(st["pressure_pa"], st["k_nm_per_rad"], p))
        cl.append(scale * _interp_clamped(st["pressure_pa"], st["c_nms_per_rad"], p))
    return {"spec": d, "k_link": kl, "c_link": cl, "payload_kg": model.payload_kg}


def body_inertial(spec: Dict[str, Any], ib: int, payload_kg: float) -> Tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre (3,), inertia about the centre (3, 3)) of body ``ib`` (0-based) in its
    own frame, payload included."""
    body = spec["bodies"][ib]
    parts: List[Tuple[float, np.ndarray, np.ndarray]] = []
    for p in body.get("parts", []):
        m = float(p["mass_kg"])
        c = np.array(p["com_m"], dtype=float)
        e = p.get("inertia_kgm2", [0.0] * 6)
        ic = np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]], dtype=float)
        if p["shape"] == "tube":
            r = p.get("radius_m")
            if r is None:
                r = spec["links"][body["link"] - 1]["radius_m"]
            l = float(p["length_m"])
            ic = ic + np.diag([m * r * r, m * (r * r / 2 + l * l / 12), m * (r * r / 2 + l * l / 12)])
        parts.append((m, c, ic))
    if spec["payload"]["body"] == ib + 1 and payload_kg > 0:
        parts.append((float(payload_kg), np.array(spec["payload"]["com_m"], dtype=float), np.zeros((3, 3))))
    mass = sum(m for m, _, _ in parts)
    if mass <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(m * c for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, ic in parts:
        r = c - com
        inertia += ic + m * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    return mass, com, inertia


# ----------------------------------------------------------------------------- MJCF
def build_mjcf(model: Any, *, dt: Optional[float] = None, integrator: str = "implicitfast", name: str = "popup") -> str:
    """MJCF text of the 7-DOF chain of ``model`` (a ``popup.Model``): same frames, masses,
    inertias, armature, springs and dampers, gravity and time step."""
    ad = arm_data(model)
    spec = ad["spec"]
    dt = model.dt if dt is None else dt
    joints = spec["joints"]
    arm_r = spec["motors"]["armature_kgm2"]
    g = spec["gravity_mps2"]
    lines = [
        f'<mujoco model="{name}">',
        '  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
        f'  <option timestep="{_f(dt)}" gravity="{_fs(g)}" integrator="{integrator}">',
        '    <flag contact="disable"/>',
        "  </option>",
        "  <worldbody>",
    ]
    motor_names: List[str] = []
    nmotor = 0
    indent = "    "
    for i, j in enumerate(joints):
        gi = np.eye(4)
        gi[:3, :3] = _rz(j.get("theta_offset", 0.0)) @ _rx(j["alpha"])
        # Rz(off) Tz(d) Tx(a) Rx(α): translation = Rz(off) (a, 0, d)
        gi[:3, 3] = _rz(j.get("theta_offset", 0.0)) @ np.array([j["a"], 0.0, j["d"]])
        rg, pg = gi[:3, :3], gi[:3, 3]
        axis = rg.T @ np.array([0.0, 0.0, 1.0])
        jpos = -rg.T @ pg
        mass, com, inertia = body_inertial(spec, i, ad["payload_kg"])
        lines.append(f'{indent}<body name="body{i + 1}" pos="{_fs(pg)}" quat="{_fs(_mat2quat(rg))}">')
        attrs = f'name="{j["name"]}" type="hinge" axis="{_fs(axis)}" pos="{_fs(jpos)}"'
        if j["kind"] == "motor":
            attrs += f' armature="{_f(arm_r[nmotor])}"'
            nmotor += 1
            motor_names.append(j["name"])
        else:
            li = j["link"] - 1
            attrs += f' stiffness="{_f(ad["k_link"][li])}" damping="{_f(ad["c_link"][li])}" springref="0"'
        lines.append(f"{indent}  <joint {attrs}/>")
        if mass > 0:
            full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
            lines.append(f'{indent}  <inertial pos="{_fs(com)}" mass="{_f(mass)}" fullinertia="{_fs(full)}"/>')
        else:
            tiny = MASSLESS_INERTIA
            lines.append(f'{indent}  <inertial pos="0 0 0" mass="{_f(MASSLESS_KG)}" diaginertia="{_fs([tiny] * 3)}"/>')
        indent += "  "
    for _ in joints:
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines.append("  </worldbody>")
    lines.append("  <actuator>")
    for n in motor_names:
        lines.append(f'    <motor name="tau_{n}" joint="{n}" gear="1" ctrllimited="false"/>')
    lines.append("  </actuator>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def load(model: Any, **kw: Any) -> Any:
    """``mujoco.MjModel`` of :func:`build_mjcf`."""
    import mujoco

    return mujoco.MjModel.from_xml_string(build_mjcf(model, **kw))


# ----------------------------------------------------------------------------- checks
def full_mass_matrix(mj: Any, data: Any, out: Optional[np.ndarray] = None) -> np.ndarray:
    """Dense joint-space mass matrix (armature included) after ``mj_forward``; works with
    MuJoCo 3.x (``mj_fullM(m, dst, d.qM)``) and 4.x (``mj_fullM(m, d, dst)``)."""
    import mujoco

    out = np.zeros((mj.nv, mj.nv)) if out is None else out
    if hasattr(data, "qM"):
        mujoco.mj_fullM(mj, out, data.qM)
    else:
        mujoco.mj_fullM(mj, data, out)
    return out


def check_against_popup(model: Any, mj: Any = None, *, n: int = 50, seed: int = 0) -> Dict[str, float]:
    """Compare MuJoCo with popup at ``n`` random configurations (joint angles uniform in
    ±π on the motors, ±0.3 rad on the bending joints). Returns the largest errors:

    * ``frame_pos`` [m], ``frame_rot`` [-]: frames 1..7 (popup ``frames``) vs MuJoCo
      ``xpos``/``xmat`` of body 1..7;
    * ``ee`` [m]: popup ``end_effector`` vs MuJoCo ``xpos`` of body 7;
    * ``mass_matrix_rel``: max |M_popup − M_mj| / max |M_mj| (mj_fullM, armature
      included in both);
    * ``gravity_rel``: popup ``gravity_torque`` G(q) vs MuJoCo ``qfrc_bias`` at zero
      velocity (= gravity only), relative to max |G|;
    * ``stiffness_rel``, ``damping_rel``: the MJCF's k and c vs ``model.stiffness``/``damping``.
    """
    import mujoco

    mj = load(model) if mj is None else mj
    data = mujoco.MjData(mj)
    rng = np.random.default_rng(seed)
    motor = list(model.core.motor_index)
    out = dict(frame_pos=0.0, frame_rot=0.0, ee=0.0, mass_matrix_rel=0.0, gravity_rel=0.0)
    nv = mj.nv
    mfull = np.zeros((nv, nv))
    for _ in range(n):
        q = rng.uniform(-0.3, 0.3, nv)
        q[motor] = rng.uniform(-np.pi, np.pi, len(motor))
        data.qpos[:] = q
        data.qvel[:] = 0.0
        mujoco.mj_forward(mj, data)
        fr = model.frames(q)
        for i in range(1, nv + 1):
            out["frame_pos"] = max(out["frame_pos"], float(np.abs(fr[i, :3, 3] - data.xpos[i]).max()))
            out["frame_rot"] = max(out["frame_rot"], float(np.abs(fr[i, :3, :3] - data.xmat[i].reshape(3, 3)).max()))
        out["ee"] = max(out["ee"], float(np.abs(model.end_effector(q) - data.xpos[nv]).max()))
        full_mass_matrix(mj, data, mfull)
        mp = model.mass_matrix(q)
        out["mass_matrix_rel"] = max(out["mass_matrix_rel"], float(np.abs(mp - mfull).max() / np.abs(mfull).max()))
        gp = np.asarray(model.core.gravity_torque(model.payload_kg, q.tolist()))
        out["gravity_rel"] = max(out["gravity_rel"], float(np.abs(gp - data.qfrc_bias).max() / np.abs(gp).max()))
    k_mj = np.array(mj.jnt_stiffness)
    c_mj = np.array(mj.dof_damping)
    out["stiffness_rel"] = float(np.abs(k_mj - model.stiffness).max() / np.abs(model.stiffness).max())
    out["damping_rel"] = float(np.abs(c_mj - model.damping).max() / np.abs(model.damping).max())
    return out


if __name__ == "__main__":  # pragma: no cover
    import popup

    m = popup.Model()
    print(build_mjcf(m))
    for k, v in check_against_popup(m).items():
        print(f"{k:>16s}: {v:.3e}")
