"""YADE script of a bonded-sphere deck (copied into the deck as script.py; run by ``yade -n -x``).

Usage (inside the deck folder's parent process, see adapters/yade.py)::

    yade -n -f2 -x DECK/script.py DECK OUT

Runs on YADE's own (system) Python: it imports nothing of this project, only numpy, json and yade. It reads
``DECK/run.npz`` (SphereRun.save) and ``DECK/yade.json`` (deck settings) and writes into ``OUT``:

- ``yade_setup.json``  what the bonding step found (bonds, joints, unbonded contacts, detection factor);
- ``yade_series.npz``  record times, kinetic energy, intact bonds (rewritten at every record: a run killed by
  its time limit still leaves it);
- ``yade_snapshot.npz`` positions, velocities and bond states at the last snapshot (taken at records, as often
  as costs at most a tenth of the run's wall time);
- ``yade_pos.bin``     positions at every record, float64 (records x n x 3), when recorded;
- ``yade_final.npz``   final positions / velocities / bond states (float64), written last;
- ``yade_bonds.npz``   with ``dump_bonds``: YADE's cohesive pairs and smooth-joint pairs after the bonding step.

Joint walls (yade.json ``joint_walls`` > 0, ``DECK/walls.npz``: run.extra joint_walls, adapters/joint_walls.py):
each wall is one fixed facet (bodies n, n + 1, ...) of a JCFpmMat of its own (``young`` from walls.npz, poisson
ks / kn, the joint friction, another material type: never bonded); the ``dropped`` spheres (the rock the walls
stand for) get groupMask 0, so they meet nothing; their bonds and joint pairs are left out of the pair rule (the
bonds reported intact).

Steps: the first step is the bonding step (every touching pair bonded by JCFpm's Ip2), after which the
per-pair rule of run.npz is applied from Python (see adapters/yade.py); the run then advances in O.run chunks
of record_steps steps and records between chunks (exact step counts, as a PyRunner with iterPeriod would).
A state with non-finite values, or a kinetic energy above 1/2 M_free (r_min / dt)^2 (some sphere then moves
more than its radius per step), stops the run as a blow-up.

Loads (run.npz ``force``, ``prescribed``, ``velocity``; absent in older decks): a constant force on a sphere is a
permanent force (``O.forces.setPermF``, kept by ForceResetter, added to gravity by NewtonIntegrator); a
prescribed sphere has blockedDOFs xyzXYZ and state.vel = its velocity (YADE moves a body with blocked DOFs at
the velocity it has, whatever the forces, and leaves it out of utils.kineticEnergy, as fixed spheres).

Lines starting with ``FATAL:`` carry the reason of a deliberate failure (the runner surfaces them);
``PROGRESS`` lines report the run's advance.
"""
import itertools
import json
import math
import os
import sys
import time
from types import SimpleNamespace

import numpy as np
from yade import O, utils
from yade.wrapper import (Body, Bo1_Facet_Aabb, Bo1_Sphere_Aabb, ForceResetter, Ig2_Facet_Sphere_ScGeom,
                          Ig2_Sphere_Sphere_ScGeom, InsertionSortCollider, InteractionLoop,
                          Ip2_JCFpmMat_JCFpmMat_JCFpmPhys, JCFpmMat, Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM,
                          NewtonIntegrator, Sphere)

HUGE = 1e300  # stands for an unbreakable bond (inf strength)
TINY = 1e-300  # a zero tensile strength: JCFpm skips the tension check when FnMax == 0


def fatal(msg, code=3):
    print("FATAL: " + msg, flush=True)
    sys.exit(code)


def save_npz(path, **arrays):
    tmp = path + ".tmp"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


def read_run(deck):
    """The run (DECK/run.npz, SphereRun.save) and the deck settings (DECK/yade.json) as one namespace; FATAL for
    a run that YADE cannot start."""
    cfg = json.load(open(os.path.join(deck, "yade.json")))
    z = np.load(os.path.join(deck, "run.npz"), allow_pickle=False)
    head = json.loads(str(z["header"]))
    centers = np.asarray(z["centers"], float)
    radii = np.asarray(z["radii"], float)
    fixed = np.asarray(z["fixed"], bool)
    n = len(radii)
    files = set(z.files)
    force = np.asarray(z["force"], float).reshape(-1, 3) if "force" in files else np.zeros((n, 3))
    prescribed = np.asarray(z["prescribed"], bool) if "prescribed" in files else np.zeros(n, bool)
    velocity = np.asarray(z["velocity"], float).reshape(-1, 3) if "velocity" in files else np.zeros((n, 3))
    prescribed &= ~fixed
    bi, bj = np.asarray(z["bond_i"], np.int64), np.asarray(z["bond_j"], np.int64)
    bkn, bks = np.asarray(z["bond_kn"], float), np.asarray(z["bond_ks"], float)
    bft, bfs = np.asarray(z["bond_ft"], float), np.asarray(z["bond_fs"], float)
    smooth = bool(head["smooth_joints"])
    ji, jj = np.asarray(z["joint_i"], np.int64), np.asarray(z["joint_j"], np.int64)
    jn = np.asarray(z["joint_normal"], float).reshape(-1, 3)
    if not smooth:
        ji, jj, jn = ji[:0], jj[:0], jn[:0]
    walls = None
    if int(cfg.get("joint_walls", 0)):  # the rock behind the walls meets nothing: its joint pairs go, its bonds
        walls = np.load(os.path.join(deck, "walls.npz"), allow_pickle=False)  # are not looked for
        drop = np.asarray(walls["dropped"], bool)
        keep = ~(drop[ji] | drop[jj])
        ji, jj, jn = ji[keep], jj[keep], jn[keep]
    bonds_needed = np.ones(len(bi), bool) if walls is None else ~(drop[bi] | drop[bj])
    dt = float(head["dt"])
    R = SimpleNamespace(
        cfg=cfg, head=head, centers=centers, radii=radii, fixed=fixed, n=n, force=force, prescribed=prescribed,
        velocity=velocity, bi=bi, bj=bj, bkn=bkn, bks=bks, bft=bft, bfs=bfs, ji=ji, jj=jj, jn=jn,
        gravity=[float(g) for g in z["gravity"]], dt=dt, steps=max(1, int(round(head["duration"] / dt))),
        rec=max(1, int(round(head["record_every"] / dt))), kn=float(head["kn"]), ks=float(head["ks"]),
        tan_phi=math.tan(math.radians(head["friction_deg"])),
        tan_joint=math.tan(math.radians(head["joint_friction_deg"])), density=float(head["density"]), m=len(bi),
        walls=walls, bonds_needed=bonds_needed)
    if n == 0:
        fatal("the run has no spheres")
    if not (np.all(radii > 0) and np.all(np.isfinite(centers))):
        fatal("radii must be > 0 and centres finite")
    if not (dt > 0 and math.isfinite(dt)):
        fatal("time step must be > 0")
    return R


def add_bodies(R):
    """The materials and the spheres as bodies, fixed and prescribed ones blocked, the constant forces; returns
    (materials, mass (n,), indices of the loaded spheres)."""
    n, radii, tan_phi = R.n, R.radii, R.tan_phi
    # -- materials: one per distinct radius, young = kn / r, so that Ip2's kn = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2)
    # equals kn for every pair of radii and ks = poisson kn (exact contact stiffness for unbonded contacts);
    # unbreakable strengths: no bond breaks during the bonding step (a sphere moving at its prescribed velocity
    # already shears its bonds then); every pair gets its own strength right after it
    ur, inv = np.unique(radii, return_inverse=True)
    mats = [JCFpmMat(type=1, young=R.kn / r, poisson=R.ks / R.kn, frictionAngle=math.atan(tan_phi), density=R.density,
                     tensileStrength=HUGE, cohesion=HUGE, jointFrictionAngle=math.atan(R.tan_joint))
            for r in ur.tolist()]
    for mat in mats:
        O.materials.append(mat)
    bodies = []
    mass = R.density * 4.0 / 3.0 * math.pi * radii ** 3
    inertia = 0.4 * mass * radii ** 2
    for k in range(n):
        b = Body()
        b.shape = Sphere(radius=float(radii[k]))
        b.material = mats[inv[k]]
        st = b.material.newAssocState()
        st.pos = st.refPos = tuple(R.centers[k])
        st.mass = float(mass[k])
        st.inertia = (float(inertia[k]),) * 3
        if R.fixed[k]:
            st.blockedDOFs = "xyzXYZ"
        elif R.prescribed[k]:  # moves at its velocity whatever the forces
            st.blockedDOFs = "xyzXYZ"
            st.vel = tuple(float(x) for x in R.velocity[k])
        b.state = st
        bodies.append(b)
    ids = O.bodies.append(bodies)
    if list(ids[:1]) not in ([0], []) or len(ids) != n:
        fatal("unexpected body ids")
    del bodies
    if R.walls is not None:
        for k in np.flatnonzero(R.walls["dropped"]).tolist():
            O.bodies[k].groupMask = 0  # meets no body
        for tri, young in zip(R.walls["triangles"], R.walls["young"]):
            mat = JCFpmMat(type=2, young=float(young), poisson=R.ks / R.kn, frictionAngle=math.atan(R.tan_joint),
                           density=R.density)
            O.materials.append(mat)
            O.bodies.append(utils.facet([tuple(map(float, p)) for p in tri], material=mat, fixed=True))
    # constant sphere forces: permanent forces (kept when ForceResetter clears the others each step)
    loaded = np.flatnonzero(np.any(R.force != 0.0, axis=1) & ~R.fixed & ~R.prescribed)
    for k in loaded.tolist():
        O.forces.setPermF(k, tuple(float(x) for x in R.force[k]))
    return mats, mass, loaded


def add_engines(R):
    """The engines of the bonding step (detection enlarged to find every pair of the bond and joint lists) and
    O.dt; returns (Bo1, Ig2, the JCFpm law, the detection factor)."""
    centers, radii, cfg = R.centers, R.radii, R.cfg
    # bonding step: detect every pair of the bond list (touching within the model's tolerance)
    pairs_i, pairs_j = np.r_[R.bi, R.ji], np.r_[R.bj, R.jj]
    ratio = 1.0
    if len(pairs_i):
        d = np.linalg.norm(centers[pairs_j] - centers[pairs_i], axis=1)
        ratio = float((d / (radii[pairs_i] + radii[pairs_j])).max())
    # pairs farther apart than max_detection_factor (ri + rj) are not touching: they stay undetected and the
    # run fails below (a bond list that names such pairs is not a contact bond list)
    f = max(float(cfg.get("detection_factor", 1.01)), ratio * 1.001)
    f = min(f, float(cfg.get("max_detection_factor", 1.2)))
    bo1 = Bo1_Sphere_Aabb(aabbEnlargeFactor=f)
    ig2 = Ig2_Sphere_Sphere_ScGeom(interactionDetectionFactor=f)
    facets = ([Bo1_Facet_Aabb()], [Ig2_Facet_Sphere_ScGeom()]) if R.walls is not None else ([], [])
    # neverErase: a smooth-joint pair that opens for a moment keeps its joint status when it closes again
    # (erased, it would come back as a plain contact that interlocks across the joint)
    law = Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM(smoothJoint=True, neverErase=True, recordCracks=False)
    O.engines = [
        ForceResetter(),
        InsertionSortCollider([bo1] + facets[0]),
        InteractionLoop([ig2] + facets[1], [Ip2_JCFpmMat_JCFpmMat_JCFpmPhys(cohesiveTresholdIteration=1)], [law]),
        NewtonIntegrator(gravity=R.gravity, damping=float(R.head["local_damping"])),
    ]
    O.dt = R.dt
    return bo1, ig2, law, f


class Records:
    """The records (t = 0 first): times, kinetic energy and intact bonds (yade_series.npz, rewritten at every
    record) and the positions (appended to yade_pos.bin when recorded)."""

    def __init__(self, R, law, out):
        self.R, self.law, self.out = R, law, out
        self.times, self.kins, self.intact = [], [], []
        self.pos_path = os.path.join(out, "yade_pos.bin")
        self.record_pos = bool(R.cfg.get("record_positions", True))
        if self.record_pos:
            open(self.pos_path, "wb").close()

    def positions(self, vel=True):
        n = self.R.n
        spheres = list(itertools.islice(O.bodies, n))  # the spheres are bodies 0..n-1, joint-wall facets after
        p = np.array([b.state.pos for b in spheres], float).reshape(n, 3)
        v = np.array([b.state.vel for b in spheres], float).reshape(n, 3) if vel else None
        return p, v

    def write_series(self):
        save_npz(os.path.join(self.out, "yade_series.npz"), time=np.array(self.times), kinetic=np.array(self.kins),
                 bonds_intact=np.array(self.intact, np.int64), steps=np.array(O.iter))

    def record(self, p=None):
        self.times.append(O.iter * self.R.dt)
        self.kins.append(float(utils.kineticEnergy()))
        self.intact.append(self.R.m - int(self.law.nbTensCracks) - int(self.law.nbShearCracks))
        if self.record_pos:
            if p is None:
                p, _ = self.positions(False)
            with open(self.pos_path, "ab") as fh:
                fh.write(np.ascontiguousarray(p, "<f8").tobytes())
        self.write_series()


def apply_pair_rule(R):
    """The exact per-pair rule after the bonding step: bond-list pairs keep a bond with their own stiffness and
    strength, joint pairs become smooth joints, every other interaction is a plain frictional contact (pairs
    detected by the enlarged factor only are erased). Returns (bond index of each pair key, bonds found, joints
    found, unbonded interactions, erased pairs)."""
    n, m, bi, bj, ji, jj, jn = R.n, R.m, R.bi, R.bj, R.ji, R.jj, R.jn
    bkn, bks, bft, bfs, tan_phi = R.bkn, R.bks, R.bft, R.bfs, R.tan_phi
    bond_of = dict(zip((bi * n + bj).tolist(), range(m)))
    joint_of = dict(zip((ji * n + jj).tolist(), range(len(ji))))
    found_b = np.zeros(m, bool)
    found_j = np.zeros(len(ji), bool)
    unbonded = 0
    apart = []
    bodies_ = O.bodies
    for I in O.interactions:
        a, c = I.id1, I.id2
        if a >= n or c >= n:
            continue  # a sphere on a joint wall's facet: JCFpm's Ip2 gave it the wall's law
        lo, hi = (a, c) if a < c else (c, a)
        key = lo * n + hi
        ph = I.phys
        k = bond_of.get(key)
        if k is not None:
            found_b[k] = True
            ph.kn = float(bkn[k])
            if ph.ks > 0:  # the shear force of the bonding step (prescribed velocities) with the bond's own ks
                ph.shearForce = ph.shearForce * (float(bks[k]) / ph.ks)
            ph.ks = float(bks[k])
            ph.FnMax = float(bft[k]) if math.isfinite(bft[k]) and bft[k] > 0 else (HUGE if bft[k] > 0 else TINY)
            ph.FsMax = float(bfs[k]) if math.isfinite(bfs[k]) else HUGE
            ph.tanFrictionAngle = tan_phi
            continue
        if ph.isCohesive:
            ph.isCohesive = False
            ph.FnMax = 0.0
            ph.FsMax = 0.0
            bodies_[a].state.nbInitBonds -= 1
            bodies_[c].state.nbInitBonds -= 1
        ph.kn = R.kn
        ph.ks = R.ks
        ph.tanFrictionAngle = tan_phi
        unbonded += 1
        k = joint_of.get(key)
        if k is not None:
            found_j[k] = True
            nv = jn[k] if a == lo else -jn[k]  # the joint normal points from id1 to id2, like I.geom.normal
            gn = I.geom.normal
            if nv[0] * gn[0] + nv[1] * gn[1] + nv[2] * gn[2] < 0:
                nv = -nv
            ph.isOnJoint = True
            ph.jointNormal = tuple(float(x) for x in nv)
            dx = np.asarray(bodies_[a].state.pos) - np.asarray(bodies_[c].state.pos)
            ph.initD = abs(float(dx @ nv))  # equilibrium gap along the joint normal: no initial force
            ph.tanFrictionAngle = R.tan_joint
        else:
            ph.initD = 0.0  # a plain contact: force from the actual overlap
            if I.geom.penetrationDepth < 0:
                apart.append((a, c))  # detected by the enlarged factor only: not touching
    for a, c in apart:
        O.interactions.erase(a, c)
    return bond_of, found_b, found_j, unbonded, apart


def dump_bonds(out):
    """yade_bonds.npz: YADE's cohesive pairs and smooth-joint pairs (yade.json dump_bonds)."""
    coh, jnt = [], []
    for I in O.interactions:
        lo, hi = min(I.id1, I.id2), max(I.id1, I.id2)
        if I.phys.isCohesive:
            coh.append((lo, hi))
        if I.phys.isOnJoint:
            jnt.append((lo, hi))
    save_npz(os.path.join(out, "yade_bonds.npz"), cohesive=np.array(coh, np.int64).reshape(-1, 2),
             joint=np.array(jnt, np.int64).reshape(-1, 2))


def retire_joints(joint_alive):
    """The (a, c, slide limit) joint pairs still on a joint: those slid past their limit are erased."""
    keep = []
    for a, c, lim in joint_alive:
        I = O.interactions[a, c] if O.interactions.has(a, c) else None
        if I is None or not I.isReal:
            continue
        if I.phys.jointCumulativeSliding >= lim:
            O.interactions.erase(a, c)
            continue
        keep.append((a, c, lim))
    return keep


def bond_states(R, bond_of):
    """(m,) bool: the bonds of the bond list still cohesive in YADE."""
    n = R.n
    state = ~R.bonds_needed  # the bonds of the rock behind joint walls: never looked at, intact
    for I in O.interactions:
        if I.phys.isCohesive and I.id1 < n and I.id2 < n:
            a, c = I.id1, I.id2
            k = bond_of.get(min(a, c) * n + max(a, c))
            if k is not None:
                state[k] = True
    return state


def step_and_record(R, recs, mass, bond_of, out):
    """Advance the run after the bonding step in O.run chunks up to each record, record, retire slid joints,
    stop on a blow-up and take snapshots (at most a tenth of the wall time); returns the stepping wall time."""
    steps, rec, dt, radii = R.steps, R.rec, R.dt, R.radii
    kins, intact = recs.kins, recs.intact
    # JCFpm switches a smooth joint off for good once its spheres slid 2 min(r_i, r_j) along it (they are no
    # longer neighbours); such interactions are erased at the records, so that a later meeting of the two
    # spheres is a plain contact again
    joint_alive = [(a, c, 2.0 * min(float(radii[a]), float(radii[c]))) for a, c in zip(R.ji.tolist(), R.jj.tolist())]
    # kinetic energy above 1/2 M_free (r_min / dt)^2 means a sphere moving more than r_min per step
    ke_limit = 0.5 * float(mass[~R.fixed & ~R.prescribed].sum()) * (float(radii.min()) / dt) ** 2
    snap_cost, snap_last, last_print = 0.0, time.time(), 0.0
    done = 1
    if rec == 1 or steps == 1:
        recs.record()  # the bonding step is the first step of the run
    t_run = time.time()
    while done < steps:
        nxt = min(steps, (done // rec + 1) * rec)
        O.run(nxt - done, True)
        done = nxt
        if done % rec == 0 or done == steps:
            take = (time.time() - snap_last) > 10.0 * snap_cost
            p = v = None
            if take or recs.record_pos:
                p, v = recs.positions(take)
            recs.record(p)
            if joint_alive:
                joint_alive = retire_joints(joint_alive)
            if not math.isfinite(kins[-1]) or (p is not None and not np.all(np.isfinite(p))):
                fatal(f"blow-up near t = {O.iter * dt:.6g} s (step {O.iter}): non-finite state (dt = {dt:.3g} s)",
                      4)
            if kins[-1] > ke_limit:  # then some sphere moves faster than r_min per step
                fatal(f"blow-up near t = {O.iter * dt:.6g} s (step {O.iter}): kinetic energy {kins[-1]:.3g} J, a "
                      f"sphere moves more than its radius per step (dt = {dt:.3g} s)", 4)
            if take and done < steps:
                t1 = time.time()
                save_npz(os.path.join(out, "yade_snapshot.npz"), time=np.array(O.iter * dt), pos=p, vel=v,
                         bond_intact=bond_states(R, bond_of), steps=np.array(O.iter))
                snap_last = time.time()
                snap_cost = snap_last - t1
            now = time.time()
            if now - last_print > 1.0 or done == steps:
                last_print = now
                print(f"PROGRESS t = {O.iter * dt:.6g} s  step {O.iter}/{steps}  kinetic {kins[-1]:.6g} J  "
                      f"bonds {intact[-1]}", flush=True)
    return time.time() - t_run


def main(deck, out):
    t_start = time.time()
    R = read_run(deck)
    m, ji = R.m, R.ji
    mats, mass, loaded = add_bodies(R)
    bo1, ig2, law, f = add_engines(R)
    recs = Records(R, law, out)
    recs.record(R.centers.copy())
    t0 = time.time()
    O.run(1, True)
    t_bond = time.time() - t0

    bo1.aabbEnlargeFactor = -1.0
    ig2.interactionDetectionFactor = -1.0
    bond_of, found_b, found_j, unbonded, apart = apply_pair_rule(R)
    missing_b = int(np.sum(~found_b & R.bonds_needed))
    missing_j = int(len(ji) - found_j.sum())
    setup = {"detection_factor": f, "bonds": m, "bonds_found": int(found_b.sum()), "bonds_missing": missing_b,
             "joints": int(len(ji)), "joints_found": int(found_j.sum()), "joints_missing": missing_j,
             "unbonded_contacts": unbonded - int(found_j.sum()) - len(apart), "materials": len(mats),
             "loaded": int(len(loaded)), "prescribed": int(R.prescribed.sum()),
             "joint_walls": 0 if R.walls is None else int(len(R.walls["young"])),
             "bonding_step_s": t_bond,
             "setup_s": time.time() - t_start}
    with open(os.path.join(out, "yade_setup.json"), "w") as fh:
        json.dump(setup, fh, indent=1)
    if missing_b or missing_j:
        fatal(f"{missing_b} of {m} bond-list pairs and {missing_j} of {len(ji)} joint pairs found no YADE "
              f"interaction at the bonding step (detection factor {f:.6g})")
    if R.cfg.get("dump_bonds"):
        dump_bonds(out)
    print(f"PROGRESS bonding step done: {int(found_b.sum())} bonds, {int(found_j.sum())} smooth joints, "
          f"{setup['unbonded_contacts']} unbonded contacts ({t_bond:.2f} s)", flush=True)

    wall_run = step_and_record(R, recs, mass, bond_of, out)
    p, v = recs.positions()
    state = bond_states(R, bond_of)
    save_npz(os.path.join(out, "yade_final.npz"), final_pos=p, final_vel=v, bond_intact=state,
             steps=np.array(O.iter), time=np.array(O.iter * R.dt), wall_run=np.array(wall_run),
             tens_cracks=np.array(int(law.nbTensCracks)), shear_cracks=np.array(int(law.nbShearCracks)))
    print(f"PROGRESS done: {O.iter} steps in {wall_run:.3f} s", flush=True)


if len(sys.argv) < 3:
    fatal("usage: yade -n -x script.py DECK OUT", 2)
main(os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2]))
