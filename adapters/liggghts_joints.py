"""LIGGGHTS decks with spheres.liggghts_joints = "open": no contact between the two sides of a joint.

LIGGGHTS-PUBLIC has no smooth joint. With run.liggghts_joints = "open" ([spheres] liggghts_joints, ``adapters
export --liggghts-joints open``) a deck writes ``neigh_modify exclude type`` between every green atom type and
every blue one (``joint_exclusions``), a smooth joint's behaviour while it is open (no force) and wrong when it
closes in compression. Type exclusion cannot name single pairs, so a run whose touching green-blue pairs are not
exactly its joint pairs is refused (``open_joint_problem``, also checked by adapters.spec when a scene asks for
it); ``open_joint_notes`` are the deck's approximations and ``joint_closure`` the error the runner reports.
Plain numpy on a SphereRun: the spec, the deck writer and the runner all read it.
"""
from __future__ import annotations

import numpy as np

GREEN_TYPES, BLUE_TYPES = (3, 7), (4, 8)  # atom_types: colour + 1, + 4 when fixed or prescribed


def open_joints(run):
    """True when the deck drops the contact across the joints (spheres.liggghts_joints = "open", smooth joints
    on, some joint pair)."""
    return run.liggghts_joints == "open" and bool(run.smooth_joints) and len(run.joint_i) > 0


def joint_exclusions(run):
    """(type a, type b) pairs of ``neigh_modify exclude type`` for spheres.liggghts_joints = "open": every green
    type with every blue type (the two sides of a joint in the colour rule); [] otherwise."""
    if not open_joints(run):
        return []
    return [(a, b) for a in GREEN_TYPES for b in BLUE_TYPES]


def green_blue_extra(run, tol=1e-6):
    """Pairs that the exclusion by type drops besides the joint pairs: green-blue pairs that touch at the start
    (centre distance <= (r_i + r_j)(1 + tol)) and are not joint pairs (e.g. a green sphere of one joint touching
    a blue one of another), as (i, j) arrays with i < j."""
    from scipy.spatial import cKDTree  # lazy: scipy.spatial takes a second to load, needed for "open" runs only

    c = np.asarray(run.colour, np.int64)
    gb = np.flatnonzero((c == 2) | (c == 3))
    if not len(gb):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    x, r = np.asarray(run.centers, float)[gb], np.asarray(run.radii, float)[gb]
    pairs = cKDTree(x).query_pairs(2.0 * float(r.max()) * (1.0 + tol), output_type="ndarray").reshape(-1, 2)
    i, j = gb[pairs[:, 0]], gb[pairs[:, 1]]
    i, j = np.minimum(i, j), np.maximum(i, j)
    d = np.linalg.norm(run.centers[j] - run.centers[i], axis=1)
    keep = (c[i] != c[j]) & (d <= (run.radii[i] + run.radii[j]) * (1.0 + tol))
    i, j = i[keep], j[keep]
    ji, jj = np.minimum(run.joint_i, run.joint_j), np.maximum(run.joint_i, run.joint_j)
    known = set(zip(ji.tolist(), jj.tolist()))
    other = np.array([(a, b) not in known for a, b in zip(i.tolist(), j.tolist())], bool)
    return i[other] if len(i) else i, j[other] if len(j) else j


def open_joint_problem(run):
    """Why the exclusion by type cannot express the run's joint pairs (None when it can): at the start the green-blue
    pairs that touch must be exactly the joint pairs. Not so when a joint pair joins two spheres of one colour or
    a touching green-blue pair is no joint pair (e.g. the geometric bond rule, or a green sphere of one joint
    touching a blue one of another)."""
    if not open_joints(run):
        return None
    c = np.asarray(run.colour, np.int64)
    same = int(np.sum(~(((c[run.joint_i] == 2) & (c[run.joint_j] == 3)) | ((c[run.joint_i] == 3) &
                                                                          (c[run.joint_j] == 2)))))
    extra = len(green_blue_extra(run)[0])
    if not (same or extra):
        return None
    what = [f"{same} joint pairs are not green-blue (they would keep their contact)"] if same else []
    what += [f"{extra} touching green-blue pairs are not joint pairs (they would lose theirs)"] if extra else []
    return ("the exclusion of green-blue contacts is not the model's joint pairs: " + " and ".join(what)
            + '; use "contact"')


def open_joint_notes(run):
    """extra.approximations of spheres.liggghts_joints = "open"."""
    out = [f'spheres.liggghts_joints = "open": no contact between green and blue spheres (neigh_modify exclude '
           f"type, green types {' '.join(map(str, GREEN_TYPES))} with blue types "
           f"{' '.join(map(str, BLUE_TYPES))}): the {len(run.joint_i)} joint pairs carry no force, as smooth joints "
           "while they are open (exact for a joint that only opens or slides open); a joint that closes in "
           "compression is not represented: its spheres pass through each other instead of pushing along the "
           "joint normal (the runner reports the largest closure, result extra 'joint_closure_max'), and "
           "spheres.joint_friction does not act",
           "green-blue pairs that first meet during the run get no contact either (the smooth-joint engines give "
           "them a plain contact)"]
    return out


def joint_closure(run, pos):
    """Closure of each joint pair at the positions `pos` [m]: its gap along the joint normal at the start minus
    now (> 0: the smooth joint would push)."""
    i, j, n = run.joint_i, run.joint_j, run.joint_normal
    d0 = np.einsum("ij,ij->i", run.centers[j] - run.centers[i], n)
    return d0 - np.einsum("ij,ij->i", pos[j] - pos[i], n)


__all__ = ["GREEN_TYPES", "BLUE_TYPES", "open_joints", "joint_exclusions", "green_blue_extra", "open_joint_problem",
           "open_joint_notes", "joint_closure"]
