"""The sphere engine's state as named bundles of numpy arrays, and the named columns of its tables.

The kernels of dda/_spheres.py (sphere-only runs) and dda/_coupled.py (spheres with moving blocks) take a
handful of these bundles instead of dozens of arrays; numba passes a namedtuple of arrays by reference, so a
kernel that writes ``bonds.intact[k]`` writes the SphereSimulation's array. dda/spheres.py builds them
(``SphereSimulation.bundles``). Inside the sphere-only loop the motion arrays are views of aligned rows (see
dda/_spheres.py), so a kernel of a stage takes them as a ``Motion`` bundle built there.

Columns read by position get named slots here: the contact-law row (``lawrow[LAW_TANPHI]``, the block
engine's order), the bond rows (``rows[k, B_KN]``), the central-bond rows, ``stats``.
"""
from __future__ import annotations

from collections import namedtuple


# the spheres: position, velocity, angular velocity (the state), radius, mass, moment of inertia, fixed and
# prescribed (kinematic) flags, constant body force
Spheres = namedtuple("Spheres", "x v w r m inertia fixed kin bforce")
# the state a stage reads and writes: position, velocity, angular velocity, and this step's force and torque
# (in a sphere-only run: views of the rows PA, PB, TQ)
Motion = namedtuple("Motion", "x v w force torque")
# one bond layout: spheres i, j; one row per bond (B_* columns: constants and state); intact flags, break time;
# bonds per sphere as CSR on the lower index (start, nbr: the partner, idx: the bond) for the pair-list build;
# the bonds with a shear spring (full: bond indices in order) and the central bonds (ks = 0: cidx their bond
# indices, cij their spheres with i stored as -1 - i while broken, crows C_* rows, cfn their normal force,
# czeta their damping ratios or an empty array for undamped ones); the hash of the pair keys i * n + j
Bonds = namedtuple("Bonds", "i j rows intact brk start nbr idx full cidx cij crows cfn czeta key_tab key_slot")
# smooth joints (dda/_spheres.py ``_joints``): spheres i, j, joint normal, tan(phi), in contact, reference gap,
# cumulative sliding, shear displacement, sign of the normal; the hash of their pair keys
Joints = namedtuple("Joints", "i j nrm tan on init slide us sgn key_tab key_slot")
# contact history, two buffers (cur[0] holds last step's contacts): count, pair key, shear displacement, elastic
# normal force, the bodies (i or -1 - wall/block, j); the hash table on last step's keys (``history_hash``)
History = namedtuple("History", "cur n key us fn ij htab")
# fixed convex walls of a sphere-only run: world vertices, face planes (normal, offset), face vertex loops
# (fv[fv_start[f]:fv_start[f + 1]]), faces of wall k (face_start[k]:face_start[k + 1]), boxes, contact law rows
Walls = namedtuple("Walls", "vert fn fd fv_start fv face_start aabb lawrow")
# the Verlet pair list: pairs[:n[0]], flag[0] = 1 asks for a rebuild, positions at the build, margin
PairList = namedtuple("PairList", "pairs n flag x_ref skin")
# the run's constants: gravity, local (Cundall) damping, viscous damping c, the sphere-sphere contact law row
Env = namedtuple("Env", "gravity local_damp visc lawrow")
# energy (the block engine's E_* columns), acc = [work of the prescribed spheres], stats (ST_* below)
Books = namedtuple("Books", "energy acc stats")

# columns of a contact-law row (ContactLaw.row: the block engine's order)
LAW_KN, LAW_KS, LAW_TANPHI, LAW_COH, LAW_TEN, LAW_ZETA = 0, 1, 2, 3, 4, 5
# energy columns: kinetic, potential, elastic, and the cumulative friction, contact damping, local damping (the
# block engine's columns, dda/_state.py: its NENERGY, with its point turnover 0 for spheres)
E_KIN, E_POT, E_ELASTIC, E_FRICTION, E_DAMPING, E_LOCAL = 0, 1, 2, 3, 4, 5
# slots of the per-step energy sums res: elastic, friction (and released), damping; bond energy (coupled runs)
R_ELASTIC, R_FRICTION, R_DAMPING, R_BOND = 0, 1, 2, 3

# columns of a bond row: rest length, kn, ks, tensile and shear strength (forces), damping ratio, shear
# displacement (3), normal force, r_i / (r_i + r_j)
B_LEN, B_KN, B_KS, B_FT, B_FS, B_ZETA, B_US, B_FN, B_RATIO = 0, 1, 2, 3, 4, 5, 6, 9, 10
NBOND_COLS = 12
# columns of a central-bond row: rest length, kn, tensile strength
C_LEN, C_KN, C_FT = 0, 1, 2

# slots of stats
ST_CONTACTS = 0     # sphere-sphere contacts
ST_WALL = 1         # sphere-wall (sphere-block) contacts
ST_BONDS = 2        # intact bonds
ST_BROKEN = 3       # bonds broken (in this call; cumulative in coupled runs)
ST_NEED = 4         # contacts needed (NEED_CAPACITY)
ST_NEED_PAIRS = 5   # pairs needed (NEED_PAIRS)
ST_JOINTS = 6       # joints in contact
ST_BUILDS = 7       # pair-list builds
NSTATS = 8

# the block side of a coupled run as the sphere kernels see it (dda/_coupled.py; the blocks' own state is the
# block engine's bundles, dda/_state.py): face vertex loops of the blocks (faces f: fv[fvs[f]:fvs[f + 1]]), a
# stamp per block and the stamp counter of the candidate search, the sphere-block contact-law row of each block
Link = namedtuple("Link", "fvs fv stamp tag lawrow")
