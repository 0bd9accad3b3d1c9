"""The Panda's inverse dynamics and TCP position as CasADi expressions.

The pinocchio wheel we use has no ``pinocchio.casadi``, so the recursive
Newton-Euler algorithm (RNEA, Featherstone's formulation, the one
``pinocchio.rnea`` implements) is written here once more, on CasADi ``SX``
symbols, from the numbers of the pinocchio model of :mod:`cosim.models.panda_model`:
joint placements, link inertias, the TCP frame and gravity.  The result is a
:class:`casadi.Function` that

* generates C (``fmus/panda_inverse_dynamics``, through
  ``python -m cosim.models.panda_inverse_dynamics_codegen``), and
* gives exact derivatives and path coefficients to the optimal-timing planner
  (:mod:`cosim.models.optimal_timing`).

Conventions are pinocchio's: a spatial motion is (linear, angular) at a frame's
origin in that frame's axes, ``liMi`` places joint ``i``'s frame in its
parent's, every Panda joint turns about its own z axis (``JointModelRZ``).
A rigid body's inertia is kept as ``(m, h, I_o)`` -- mass, first moment
``h = m c`` and rotational inertia about the frame origin -- because these add
up when the payload is fixed to link 7 (no division by the total mass).

Promised (``tests/models/test_panda_inverse_dynamics_fmu.py``): the torques equal
``pinocchio.rnea`` of :func:`models.panda_model.panda_model` with the same
payload to 1e-10 N.m, the TCP position equals pinocchio's forward kinematics.
"""

from __future__ import annotations

import hashlib
import math
import re
import tempfile
from pathlib import Path
from typing import Callable, Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

from .panda_model import EE_FRAME, N_JOINTS, panda_model

FUNCTION_NAME = "panda_id"
INPUT_NAMES = ("q", "qd", "qdd", "payload_mass", "payload_com", "payload_inertia")
OUTPUT_NAMES = ("tau", "ee_pos")


def _skew(v):
    return ca.vertcat(ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]), ca.horzcat(-v[1], v[0], 0))


def _rot_z(angle):
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


def _body_inertia(inertia: pin.Inertia) -> tuple:
    """(m, h, I_o) of a numeric pinocchio inertia, as CasADi constants."""
    m = float(inertia.mass)
    c = np.asarray(inertia.lever, dtype=float)
    i_c = np.asarray(inertia.inertia, dtype=float)
    # |c|^2 as three Python float products summed left to right: every step is one IEEE rounding on any machine.
    # c.dot(c) went to OpenBLAS's ddot, whose kernel (picked per CPU, or by OPENBLAS_CORETYPE) may fuse or reorder
    # it: with the AVX-512 kernels one inertia came out one ulp off and the checked-in C no longer matched.
    cx, cy, cz = (float(x) for x in c)
    i_o = i_c + m * ((cx * cx + cy * cy + cz * cz) * np.eye(3) - np.outer(c, c))  # parallel-axis theorem
    return ca.DM(m), ca.DM(m * c), ca.DM(i_o)


def _payload_inertia(mass, com, inertia6, placement: pin.SE3) -> tuple:
    """(m, h, I_o) of the payload (given in the TCP frame) in the frame of link 7, symbolic."""
    ixx, iyy, izz, ixy, ixz, iyz = (inertia6[k] for k in range(6))
    i_c = ca.vertcat(ca.horzcat(ixx, ixy, ixz), ca.horzcat(ixy, iyy, iyz), ca.horzcat(ixz, iyz, izz))
    rot, trans = ca.DM(placement.rotation), ca.DM(placement.translation)
    c = ca.mtimes(rot, com) + trans
    i_c = ca.mtimes(ca.mtimes(rot, i_c), rot.T)
    i_o = i_c + mass * (ca.dot(c, c) * ca.DM.eye(3) - ca.mtimes(c, c.T))
    return mass, mass * c, i_o


def _apply_inertia(body, lin, ang):
    """Force (f, n) = inertia * motion (lin, ang) with the inertia as (m, h, I_o)."""
    m, h, i_o = body
    return m * lin - ca.cross(h, ang), ca.mtimes(i_o, ang) + ca.cross(h, lin)


def symbolic_inverse_dynamics(model: pin.Model | None = None) -> ca.Function:
    """``panda_id(q, qd, qdd, payload_mass, payload_com, payload_inertia) -> (tau, ee_pos)``.

    ``model`` is the payload-free 7-joint Panda (default
    :func:`models.panda_model.panda_model`); the payload arguments mean what
    they mean in :func:`models.panda_model.panda_model` (mass in kg, centre of
    mass in the TCP frame, ``Ixx Iyy Izz Ixy Ixz Iyz`` about it).  ``tau`` is
    RNEA (N.m), ``ee_pos`` the TCP position in the base frame (m).

    Raises ValueError if ``model`` is not a chain of 7 revolute-z joints.
    """
    model = panda_model() if model is None else model
    if model.nq != N_JOINTS or any(model.joints[i].shortname() != "JointModelRZ" for i in range(1, model.njoints)):
        raise ValueError("symbolic_inverse_dynamics expects the 7 revolute-z joints of the Panda")
    q, qd, qdd = (ca.SX.sym(n, N_JOINTS) for n in INPUT_NAMES[:3])
    payload_mass, payload_com, payload_inertia = ca.SX.sym("payload_mass"), ca.SX.sym("payload_com", 3), ca.SX.sym("payload_inertia", 6)

    tcp = model.frames[model.getFrameId(EE_FRAME)]
    bodies = [_body_inertia(model.inertias[i]) for i in range(model.njoints)]
    payload = _payload_inertia(payload_mass, payload_com, payload_inertia, tcp.placement)
    j = tcp.parentJoint
    bodies[j] = tuple(a + b for a, b in zip(bodies[j], payload))

    z = ca.DM([0.0, 0.0, 1.0])
    gravity = np.asarray(model.gravity.linear, dtype=float)
    # forward pass: placements, velocities, accelerations (gravity as a base acceleration)
    rot, pos = [None] * model.njoints, [None] * model.njoints  # liMi
    o_rot, o_pos = [ca.DM.eye(3)] + [None] * N_JOINTS, [ca.DM.zeros(3)] + [None] * N_JOINTS  # oMi
    v = [(ca.DM.zeros(3), ca.DM.zeros(3))] + [None] * N_JOINTS
    a = [(ca.DM(-gravity), ca.DM.zeros(3))] + [None] * N_JOINTS
    forces = [None] * model.njoints
    for i in range(1, model.njoints):
        k, parent, placement = i - 1, model.parents[i], model.jointPlacements[i]
        rot[i] = ca.mtimes(ca.DM(placement.rotation), _rot_z(q[k]))
        pos[i] = ca.DM(placement.translation)
        o_rot[i] = ca.mtimes(o_rot[parent], rot[i])
        o_pos[i] = o_pos[parent] + ca.mtimes(o_rot[parent], pos[i])
        rt = rot[i].T
        (pv, pw), (pa, paw) = v[parent], a[parent]
        lin = ca.mtimes(rt, pv - ca.cross(pos[i], pw))  # liMi^-1 acting on the parent's motion
        ang = ca.mtimes(rt, pw) + z * qd[k]
        v[i] = (lin, ang)
        # a_i = liMi^-1 a_parent + S qdd + v_i x (S qd)
        jw = z * qd[k]
        a_lin = ca.mtimes(rt, pa - ca.cross(pos[i], paw)) + ca.cross(lin, jw)
        a_ang = ca.mtimes(rt, paw) + z * qdd[k] + ca.cross(ang, jw)
        a[i] = (a_lin, a_ang)
        # f_i = I a_i + v_i x* (I v_i)
        f_a, n_a = _apply_inertia(bodies[i], *a[i])
        f_v, n_v = _apply_inertia(bodies[i], lin, ang)
        forces[i] = [f_a + ca.cross(ang, f_v), n_a + ca.cross(ang, n_v) + ca.cross(lin, f_v)]
    # backward pass: joint torques, forces handed to the parents
    tau = [None] * N_JOINTS
    for i in range(model.njoints - 1, 0, -1):
        f, n = forces[i]
        tau[i - 1] = n[2]
        parent = model.parents[i]
        if parent > 0:
            f_p = ca.mtimes(rot[i], f)
            forces[parent][0] += f_p
            forces[parent][1] += ca.mtimes(rot[i], n) + ca.cross(pos[i], f_p)
    ee_pos = o_pos[j] + ca.mtimes(o_rot[j], ca.DM(tcp.placement.translation))
    return ca.Function(FUNCTION_NAME, [q, qd, qdd, payload_mass, payload_com, payload_inertia],
                       [ca.vertcat(*tau), ee_pos], list(INPUT_NAMES), list(OUTPUT_NAMES))


# generated C, checked in ------------------------------------------------------------------------

def write_generated_c(functions: Sequence[ca.Function], basename: str, prefix: str, out_dir: Path,
                      command: str) -> list[Path]:
    """CasADi's C for ``functions`` as ``basename``.c and .h in ``out_dir`` (made if missing); their paths.

    Each file starts with a banner naming the module that regenerates it
    (``python -m command``) and the URDF's sha256.  ``prefix`` names the
    generated helpers, so two generated files can be linked into one library.
    """
    from .panda_model import urdf_path

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    urdf = Path(urdf_path())
    digest = hashlib.sha256(urdf.read_bytes()).hexdigest()
    banner = (f"/* GENERATED by `python -m {command}` -- do not edit.\n"
              f" * Source: models/panda_symbolic.py on {urdf.name} (example-robot-data), sha256 {digest}. */\n")
    with tempfile.TemporaryDirectory() as tmp:
        generator = ca.CodeGenerator(f"{basename}.c", {"with_header": True, "casadi_real": "double",
                                                       "casadi_int": "int", "prefix": prefix})
        for function in functions:
            generator.add(function)
        generator.generate(tmp + "/")
        paths = []
        for name in (f"{basename}.c", f"{basename}.h"):
            target = out_dir / name
            target.write_text(banner + (Path(tmp) / name).read_text())
            paths.append(target)
    return paths


# a numeric literal of generated C (not a digit inside an identifier or a hex digest): 12, 5.28e-02, .5, 1.
_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?![\w.])")
#: how far a numeric literal of a regeneration may be from the checked-in one, in units in the last place
#: (4 ulp is at most 8.9e-16 relative): the last bit of a constant depends on the CPU's BLAS/libm kernels
GENERATED_LITERAL_ULPS = 4


def same_generated_code(checked_in: str, fresh: str, ulps: int = GENERATED_LITERAL_ULPS) -> bool:
    """Whether two generated C texts are the same code: the same text with every numeric literal replaced by a
    placeholder (every operation, identifier, index, comment, the banner: exact), and each pair of literals
    within ``ulps`` units in the last place of the larger one (a constant's last bits: to an ulp).

    Integers (indices, sizes) are literals too, and differ by at least 1, far more than a few ulp of them.
    """
    if _NUMBER.sub("#", checked_in) != _NUMBER.sub("#", fresh):
        return False
    for a, b in zip(_NUMBER.findall(checked_in), _NUMBER.findall(fresh)):
        if a != b:
            x, y = float(a), float(b)
            if abs(x - y) > ulps * math.ulp(max(abs(x), abs(y))):
                return False
    return True


def stale_generated_files(generate: Callable[[Path], list[Path]], folder: Path) -> list[str]:
    """Names of the files ``generate(out_dir)`` writes that are missing from ``folder`` or are other code there.

    Compared by :func:`same_generated_code`: the text exactly, the numeric literals to a few ulp, because the last
    bit of a constant folded from pinocchio's numbers may depend on the machine's BLAS kernel or libm.
    """
    with tempfile.TemporaryDirectory() as tmp:
        fresh = generate(Path(tmp))
        return [f.name for f in fresh
                if not (folder / f.name).is_file()
                or not same_generated_code((folder / f.name).read_text(), f.read_text())]


def regenerate_or_check(argv: list[str] | None, module: str, description: str,
                        generate: Callable[[Path], list[Path]], folder: Path) -> int:
    """The command line of a module whose C is generated and checked in (``python -m module [--check]``).

    Without ``--check``: rewrite the files into ``folder`` and print their
    paths.  With it: compare only; exit code 1 (naming the stale files and the
    command that rewrites them) if they differ from a fresh generation.
    """
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 if the checked-in files are out of date")
    args = parser.parse_args(argv)
    if args.check:
        stale = stale_generated_files(generate, folder)
        if stale:
            print(f"out of date in {folder}: {', '.join(stale)}; run python -m {module}", file=sys.stderr)
            return 1
        print("up to date")
        return 0
    for path in generate(folder):
        print(path)
    return 0
