"""The thesis's published numbers, as printed, for the scripts that reproduce them.

Source: "Control methodology for an inflatable robotic arm" (Politecnico di Torino,
Simscape/Simulink models); each constant names its table or section. Units as in the
thesis: rad/s for frequencies and amplitudes, dB for peaks, N·m/rad for stiffness.
Typos are kept as printed and marked ``sic``; nothing here is read from outside the
repository.
"""

from __future__ import annotations

import math
from typing import Dict, Optional, Tuple

# ----------------------------------------------------------------------------- chapter 2
TABLE3: Dict[float, Tuple[float, float, float]] = {
    # Table 3: p [kPa] -> (k [N·m/rad], c [N·m·s/rad], f_s [Hz]) of the 55 mm link
    10: (321, 0.557, 15.04),
    20: (347, 0.547, 15.63),
    30: (360, 0.463, 15.94),
    40: (370, 0.450, 16.17),
    50: (382, 0.433, 16.44),
    60: (388, 0.429, 16.56),
    70: (392, 0.412, 16.65),
    80: (401, 0.407, 16.83),
    90: (405, 0.406, 16.93),
}

FEM_FIT = {
    # Section 2.3: Simscape flexible cylindrical beam fitted to the PRBM link's tip
    # displacement (payload under gravity), Rayleigh damping C = μM + λK, μ neglected.
    "start": {"e_pa": 0.4e9, "lambda_s": 0.002},
    "fit1": {"wall_m": 1.2e-3, "payload_kg": 1.0, "payload_caption_kg": 2.0, "e_pa": 0.55741e9, "lambda_s": 3.896e4},
    "fit2": {"wall_m": 0.8e-3, "payload_kg": 2.0, "e_pa": 794.9e6, "lambda_s": 3.4919e4},  # printed as "μ" (sic)
}

# ----------------------------------------------------------------------------- chapter 6.1
AMPLITUDES = (3.0, 1.0, 0.1)
"""Sine amplitudes [rad/s] of the velocity reference in Tables 5–8."""

TABLES_5_7: Dict[float, Dict[str, Dict[float, float]]] = {
    # Tables 5 (2 kg), 6 (1 kg), 7 (0 kg): gravity on, q0 = 0°, velocity PI Kp 5000, Ki 100;
    # link model -> amplitude [rad/s] -> cut-off [rad/s]
    2.0: {
        "rigid": {3.0: 12.9, 1.0: 38.3, 0.1: 376.0},
        "fem": {3.0: 49.2, 1.0: 151.3, 0.1: 707.0},
        "prbm": {3.0: 50.0, 1.0: 151.0, 0.1: 707.0},
    },
    1.0: {
        "rigid": {3.0: 25.0, 1.0: 77.0, 0.1: 580.0},
        "fem": {3.0: 49.5, 1.0: 151.8, 0.1: 709.0},
        "prbm": {3.0: 50.0, 1.0: 165.0, 0.1: 710.0},
    },
    0.0: {
        "rigid": {3.0: 25.0, 1.0: 75.0, 0.1: 580.0},
        "fem": {3.0: 49.6, 1.0: 151.8, 0.1: 709.7},
        "prbm": {3.0: 47.8, 1.0: 152.0, 0.1: 710.0},
    },
}

TABLE8: Dict[float, float] = {3.0: 49.1, 1.0: 151.5, 0.1: 707.0}
"""Table 8: motoreducer alone (no link, no payload): amplitude [rad/s] -> cut-off [rad/s]."""

TABLE9: Dict[float, float] = {1.0: 0.49, 10.0: 5.6, 100.0: 56.0, 1000.0: 152.0, 5000.0: 152.0}
"""Table 9: motoreducer alone, amplitude 1 rad/s: velocity Kp -> cut-off [rad/s]."""
TABLE9_AMPLITUDE = 1.0

VEL_KP, VEL_KI = 5000.0, 100.0
"""Velocity PI of chapters 4–7 (drive units)."""

# ----------------------------------------------------------------------------- chapter 6.2
LINK_FRF: Dict[int, Dict[str, object]] = {
    # Tables 10–15: input q̇3 (feedback joint velocity), output the tip's angular velocity
    # about the link's y axis; one link (link 2), payload at the tip, q0 = 0°.
    # cut-off [rad/s] (None: "> 1000"), peak [dB], resonance [rad/s]
    10: {"gravity": True, "payload": 2.0, "fem": (430.0, 23.5, 7.8), "prbm": (13.5, 21.0, 7.85)},
    11: {"gravity": True, "payload": 1.0, "fem": (None, 12.0, 12.5), "prbm": (19.5, 8.0, 11.0)},
    12: {"gravity": True, "payload": 0.0, "fem": (None, 13.5, 55.0), "prbm": (147.0, 10.0, 54.5)},
    13: {"gravity": False, "payload": 2.0, "fem": (430.0, 24.0, 7.85), "prbm": (13.5, 20.0, 7.85)},
    14: {"gravity": False, "payload": 1.0, "fem": (None, 12.0, 12.7), "prbm": (19.2, 10.0, 7.8)},  # 7.8 (sic?)
    15: {"gravity": False, "payload": 0.0, "fem": (None, 13.5, 54.5), "prbm": (145.0, 9.7, 145.0)},  # 145 (sic?)
}
LINK_FRF_SIC = {(14, "res"), (15, "res")}
"""Entries the spec marks (sic?): Table 14's PRBM resonance 7.8 and Table 15's 145 rad/s."""

LPF_CORNER = 13.5
"""Low-pass corner [rad/s] of the damping PIDs (chapters 7–8) = Table 10's PRBM cut-off."""

# ----------------------------------------------------------------------------- chapters 4, 5, 7, 8
CH4 = {"step": math.pi / 2, "pos": (20.0, 0.25), "vel": (5000.0, 100.0)}
CH5 = {"q0": 0.0, "p_pa": 30e3, "payload": 2.0, "m_w": 12.32}

CH7_POS = (30.0, 0.25)
CH7_VEL = (5000.0, 100.0)
CH7: Dict[int, Dict[str, object]] = {
    # chapter 7: payload 2 kg, low-pass 13.5 rad/s on the relative tip acceleration
    1: {"system": "one link", "ref": "step", "amp": math.pi / 2, "joints": (3,), "gravity": False, "q0": (0.0, 0.0, 0.0), "pid": (1.0, 0.01, 0.01)},
    2: {"system": "one link", "ref": "square", "amp": None, "joints": (3,), "gravity": False, "q0": (0.0, 0.0, 0.0), "pid": (1.0, 0.01, 0.01)},
    3: {"system": "one link", "ref": "step", "amp": math.pi / 2, "joints": (3,), "gravity": True, "q0": (0.0, 0.0, 0.0), "pid": (70.0, 5.0, 0.1)},
    4: {"system": "one link", "ref": "square", "amp": None, "joints": (3,), "gravity": True, "q0": (0.0, 0.0, 0.0), "pid": (70.0, 5.0, 0.1)},
    5: {"system": "whole arm", "ref": "step", "amp": math.pi / 2, "joints": (3,), "gravity": True, "q0": (0.0, math.pi / 2, 0.0), "pid": (70.0, 0.0, 0.0)},
    6: {"system": "whole arm", "ref": "step", "amp": math.pi / 4, "joints": (2, 3), "gravity": True, "q0": (0.0, math.pi / 2, 0.0), "pid": (70.0, 100.0, 20.0)},
    7: {"system": "whole arm", "ref": "step", "amp": math.pi / 4, "joints": (2, 3), "gravity": True, "q0": (0.0, math.pi / 2, 0.0), "pid": ((70.0, 60.0, 20.0), 0.0, 0.0)},
}
CH7_STEP_DELAY = 2.0
"""Steps start after 2 s [s] (chapter 7)."""

CH8 = {
    "target": (-0.8, -0.8, 0.9),
    "q0": (0.0, math.radians(60.0), math.radians(-120.0)),
    "vel": (1000.0, 10.0),
    "gravity": False,
    "payloads": (2.0, 1.0, 0.0),
    "sim1": {"kp": (0.0, 50.0, 50.0), "ki": (0.0, 0.0, 0.0), "kd": (0.0, 0.0, 0.0)},
    "sim2": {"kp": (30.0, 60.0, 70.0), "ki": (0.1, 0.1, 0.1), "kd": (0.1, 0.1, 0.1)},
}


def link_frf_entry(table: int, model: str, what: str) -> Optional[float]:
    """One number of Tables 10–15: ``model`` "fem" or "prbm", ``what`` "cutoff" [rad/s],
    "peak" [dB] or "res" [rad/s]; None where the thesis printed "> 1000"."""
    i = {"cutoff": 0, "peak": 1, "res": 2}[what]
    return LINK_FRF[table][model][i]  # type: ignore[index]
