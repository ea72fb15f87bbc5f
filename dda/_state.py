"""The block engine's state as named bundles of numpy arrays, and the named slots of its tables.

The kernels of the time loop (dda/_integrate.py and the stages it calls) take a handful of these bundles instead
of dozens of arrays; numba passes a namedtuple of arrays by reference, so a kernel that writes ``blocks.pos[i]``
writes the Simulation's array. dda/simulation.py builds them (``Simulation.bundles``), dda/_coupled.py passes
them on. Bundles are immutable: the arrays a step replaces (grids, pair lists) travel in ``Lists``, which
``run_chunk`` returns anew.

Tables read by position elsewhere get named slots here: the columns of the contact-law table
(``lawtab[mi, mj, LAW_TANPHI]``), the energy columns and the slots of ``stats``.
"""
from __future__ import annotations

from collections import namedtuple

# the pose, velocity and the fixed per-block properties
Blocks = namedtuple("Blocks", "pos vel quat angmom mass inertia fixed kin wpres material size_b dof12")
# deformable blocks (dda/_deform.py): body-frame strains, strain rates, angular velocity; their matrices
Deform = namedtuple("Deform", "strain srate wb m9 m9inv vc")
# gravity, constant loads (body force, point loads of block i: rows pl_start[i]:pl_start[i+1]) and the external
# per-step force, torque and strain force (the spheres' reactions; empty arrays for block-only runs)
Loads = namedtuple("Loads", "gravity bforce pl_start pl_r pl_f fext text qext")
# the forces of one step: world force and torque about the centroid, strain part of T^T f (deformable blocks)
# dsum, dscale: each block's dashpot rates this step and its dashpots' scale (dda/_contact.py)
Forces = namedtuple("Forces", "force torque qs dsum dscale")
# per-block ranges (vs, fs, es) of the body-frame vertices / face planes, their world images, boxes, half-edges
Geometry = namedtuple("Geometry", "vs fs es vloc nloc dloc vert fnw fdw aabb "
                                  "he_origin he_next he_pair he_face vert_he edge_he")
# the broad phase's cell size, cell-box margin, search gap and per-block cells (dda/_broad.py)
Grid = namedtuple("Grid", "S margin gap cellbox large stamp tag")
# what a step may replace: the awake moving blocks, the moving and static grids, the large blocks, pair lists
Lists = namedtuple("Lists", "active mstart mentries fstart fentries large_list pa pb")
# sleeping: the movable blocks, flags, calm-step counters, potential of each sleeping block, the parameters
# [on, velocity, acceleration, steps], the calm window's velocity sums per block (nb x 12: sum v_k and sum k v_k of
# v = (velocity, size x angular velocity), k = 0.. the window's steps), each rigid block's kinetic energy in this
# step's books (integrate's product form), the blocks woken and not yet through a window
Sleep = namedtuple("Sleep", "movable asleep calm pe_sl par sw ke woke")
# contact history, two buffers (cur[0] the current one): per pair key, blocks a and b, common-plane normal,
# point count; per point feature id, shear displacement, state, bond, position, elastic normal force, depth;
# the hash table on the pair key
Contacts = namedtuple("Contacts", "cur n_pair key a b nrm npt pid us state bond pos fn depth fd htab")
# contact-law table lawtab[material a, material b, LAW_*] and the gap within which bonded contacts are kept; the
# face kinds of a cut block model (dda/_kinds.py: per face its law row, where the row holds, the disc or triangle;
# the intact-rock row; empty arrays: the materials decide)
Law = namedtuple("Law", "tab keep_gap face_row face_shape face_geo intact_row")
# energy (E_* columns), acc = [work of the prescribed blocks, potential of the sleeping ones], stats (ST_*)
Books = namedtuple("Books", "energy acc stats")

# all of them, in the order of run_chunk's arguments after the step parameters (Simulation.bundles)
State = namedtuple("State", "blocks deform loads forces geometry grid lists sleep contacts law books")

# scratch arrays of run_chunk (allocated once per chunk, not per step): rotation matrix, angular velocities,
# quaternion, the pair's normal, point force, relative velocity, shear displacement, the pair's contact points
# (position, depth, feature id), which of last step's points found a successor, the separating-axis normal,
# contact_points' scratch; fixed-or-asleep flags, sleep vetoes and the blocks to wake
Work = namedtuple("Work", "R w_old w_new Lnew qh nrm fpt vrel us p_pos p_depth p_id matched n_sat scr iscr "
                          "static veto wake_list")

# columns of the contact-law table (ContactLaw.row)
LAW_KN, LAW_KS, LAW_TANPHI, LAW_COH, LAW_TEN, LAW_ZETA = 0, 1, 2, 3, 4, 5
NLAW = 6

# energy columns: kinetic, potential, elastic, and the cumulative friction, contact damping, local damping and
# point turnover (the spring energy of contact points that the contact geometry created or dropped while loaded:
# released minus created; dda/_narrow.py)
E_KIN, E_POT, E_ELASTIC, E_FRICTION, E_DAMPING, E_LOCAL, E_TURNOVER = 0, 1, 2, 3, 4, 5, 6
NENERGY = 7
# acc slots
ACC_DRIVER, ACC_SLEEPING = 0, 1

# slots of stats
ST_STEPS = 0        # steps done
ST_STATUS = 1       # OK, NEED_CAPACITY, BLOWUP
ST_NEED = 2         # pairs needed (NEED_CAPACITY)
ST_FCP_ITER = 3     # FCP iterations of the chunk
ST_MAXDEPTH = 4     # deepest contact point
ST_CONTACTS = 5     # contacts (pairs with points)
ST_POINTS = 6       # contact points
ST_SLIDING = 7      # sliding points
ST_PAIRS = 8        # candidate pairs
ST_SAT = 9          # separating-axis searches that improved the plane (chunk)
ST_AWAKE = 10       # awake moving blocks
ST_BLOCK_STEPS = 11  # block-steps integrated in the chunk (the awake blocks of each step, summed)
NSTATS = 12

# slots of one step's running sums (run_chunk's `tally`, float) and counters (`count`, integer; FIT and SAT add up
# over the chunk)
T_ELASTIC, T_FRICTION, T_DAMPING, T_LOCAL, T_KIN, T_POT, T_MAXDEPTH, T_TURNOVER = 0, 1, 2, 3, 4, 5, 6, 7
NTALLY = 8
C_NEW, C_WAKE, C_CONTACTS, C_POINTS, C_SLIDING, C_SAT, C_FIT = 0, 1, 2, 3, 4, 5, 6
NCOUNT = 7
