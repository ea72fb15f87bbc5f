"""Numba kernels of the random packer's state: the bucket queue of candidates, zones, candidate slots and
the state a packing starts from and ends with (see sgim/_rpack.py for the algorithm, fill for the loop)."""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from . import _meshq as MQ
from ._rpgrid import grid_insert
from ._rppocket import SUP_NONE, SUP_PLANE0
from ._rpregion import near_distance

BIG = 1e300
PCAP = 16384  # pairs solved in one chunk (>= the neighbour cap, so one neighbour's pairs always fit)

# what a packing is asked: the box, overlap tolerance, grid (sgim._rpgrid.Grid), constraint meshes
# (sgim._meshq data), excavation (sgim._rpregion.Exc), radius mode and its data (constant radius, radius
# sequence, grading law (rf, rc, df, dc, spread), the named objects' meshes with their offsets, discs
# (centres, normals, radii, half thickness) and spread factors)
PackArgs = namedtuple("PackArgs", "lo hi tol G Dc exc mode rconst rseq grade Dg goff discs fseq")
# the placed spheres (grown with the packing when one zone): centres, radii, both side by side, bounds of
# the grading distance, the grid's next links, the tangent plane on the nearest constraint surface and its
# mesh, the newest queued candidate each sphere made
Spheres = namedtuple("Spheres", "X R XR DGL DGH nxt FP FPk ohead")
# candidate slots (grown when one zone): position and radius, integer record, stored planes, free list
Cands = namedtuple("Cands", "CF CI cpl freel")
# queues and zones: bucket heads per zone, zone counters, zones, sphere and candidate ranges of each zone,
# counters, the radius pool's state and the pool, the queue's origin and scale
Queue = namedtuple("Queue", "bhead ZS ZG sbase send cbase cend CNT MS pool qz0 qinv")
# work arrays of one thread (see fill)
Work = namedtuple("Work", "nb nbx nbr nbh NT SQ PP OUT pl plid plown")


# ---------------------------------------------------------------------------
# bucket queue of candidates (the packer's priority queue)
#
# Buckets of height QRES x the smallest level's largest radius hold doubly linked lists of
# candidates (newest first); bmin never exceeds the lowest non-empty bucket.  Every candidate
# made by a placed sphere is also on its creator's list, so that the candidates a new sphere
# covers are removed when it is placed (its neighbours' lists) instead of being popped stale.

QRES = 0.1


@njit(cache=True, inline="always")
def q_bucket(key, qz0, qinv, nbk):
    return min(max(int((key - qz0) * qinv), 0), nbk - 1)


@njit(cache=True, inline="always")
def q_push(bhead, CI, ohead, c, b, owner):
    """Queue candidate c in bucket b and on its creator's list (owner < 0: none).
    CI[c]: 4 bucket, 5 next, 6 previous in the bucket; 7 next, 8 previous on the creator's list."""
    h = bhead[b]
    CI[c, 4] = b
    CI[c, 5] = h
    CI[c, 6] = -1
    if h >= 0:
        CI[h, 6] = c
    bhead[b] = c
    if owner >= 0:
        h = ohead[owner]
        CI[c, 7] = h
        CI[c, 8] = -1
        if h >= 0:
            CI[h, 8] = c
        ohead[owner] = c


@njit(cache=True, inline="always")
def q_remove(bhead, CI, ohead, c, owner):
    p, q = CI[c, 6], CI[c, 5]
    if p >= 0:
        CI[p, 5] = q
    else:
        bhead[CI[c, 4]] = q
    if q >= 0:
        CI[q, 6] = p
    if owner >= 0:
        p, q = CI[c, 8], CI[c, 7]
        if p >= 0:
            CI[p, 7] = q
        else:
            ohead[owner] = q
        if q >= 0:
            CI[q, 8] = p


# ---------------------------------------------------------------------------
# the packer's state


@njit(cache=True)
def _grow2(a, n):
    b = np.empty((n, a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _grow1(a, n, fill):
    b = np.full(n, fill, a.dtype)
    b[:a.shape[0]] = a
    return b


# zones (parallel packing of a constant radius): the region is cut across its longer horizontal
# axis into two halves A, B and a strip of half width w around the cut, itself in two sides
# SA, SB.  The packing rises in bands: A and B fill their pockets below the band's top at the same
# time, then the strip fills its own.  w is wide enough (see sgim/rpack.py) that a sphere placed
# in A reads and writes nothing that B reads or writes, so the result does not depend on the
# threads, only on the zones.  One zone (0) when not parallel.
ZSN, ZCN, ZNF, ZHN, ZBM = 0, 1, 2, 3, 4  # per zone: spheres, fresh candidate slots used, free slots, queued, lowest bucket
ST_DONE, ST_PAUSE, ST_FULL = 0, 1, 2


@njit(cache=True, inline="always")
def zone_of(ZG, x, y):
    """ZG = (parallel, axis, cut, half width): 0 (A), 1 (B), 2 (SA), 3 (SB); 0 when not parallel."""
    if ZG[0] == 0.0:
        return 0
    v = x if ZG[1] == 0.0 else y
    if v < ZG[2] - ZG[3]:
        return 0
    if v >= ZG[2] + ZG[3]:
        return 1
    return 2 if v < ZG[2] else 3


@njit(cache=True)
def alloc_cand(kz, Q, C, grow):
    """A candidate slot in zone kz (its free list first): (slot or -1 when full, the candidates C
    (Cands), grown when grow)."""
    ZS, cbase, cend = Q.ZS, Q.cbase, Q.cend
    if ZS[kz, ZNF] > 0:
        ZS[kz, ZNF] -= 1
        return C.freel[cbase[kz] + ZS[kz, ZNF]], C
    c = cbase[kz] + ZS[kz, ZCN]
    if c == cend[kz]:
        if not grow:
            return -1, C
        ncap = 2 * C.CF.shape[0]  # one zone: its range is the whole array
        C = Cands(_grow2(C.CF, ncap), _grow2(C.CI, ncap), _grow2(C.cpl, ncap), _grow1(C.freel, ncap, 0))
        cend[kz] = ncap
    ZS[kz, ZCN] += 1
    return c, C


@njit(cache=True, inline="always")
def push_pocket(q, rn, i, s1, s2, sp, Q, C, grow, ohead, cnt):
    """Queue the pocket (q = (qx, qy, qz), rn) made by sphere i with supports s1, s2 (spheres, walls,
    or the stored plane sp = (snx, sny, snz, sh) when s2 is SUP_PLANE0) in the zone of q.  Returns
    (slot or -1 when the zone is full, the candidates, grown when grow)."""
    qx, qy, qz = q
    snx, sny, snz, sh = sp
    ZS, bhead = Q.ZS, Q.bhead
    kz = zone_of(Q.ZG, qx, qy)
    cc, C = alloc_cand(kz, Q, C, grow)
    if cc < 0:
        return cc, C
    CF, CI, cpl = C.CF, C.CI, C.cpl
    CI[cc, 9] = kz
    CF[cc, 0], CF[cc, 1], CF[cc, 2] = qx, qy, qz
    CF[cc, 3] = rn
    CI[cc, 3] = i + 1
    CI[cc, 0], CI[cc, 1], CI[cc, 2] = i, s1, s2
    if s2 == SUP_PLANE0:
        cpl[cc, 0], cpl[cc, 1], cpl[cc, 2], cpl[cc, 3] = snx, sny, snz, sh
    bq = q_bucket(qz, Q.qz0, Q.qinv, bhead.shape[1])
    q_push(bhead[kz], CI, ohead, cc, bq, i)
    ZS[kz, ZBM] = min(ZS[kz, ZBM], bq)
    ZS[kz, ZHN] += 1
    cnt[2] += 1
    return cc, C


@njit(cache=True, inline="always")
def free_cand(c, Q, CI, freel):
    ZS = Q.ZS
    kz = CI[c, 9]
    freel[Q.cbase[kz] + ZS[kz, ZNF]] = c
    ZS[kz, ZNF] += 1


@njit(cache=True, error_model="numpy")
def pack_init(P, pool_size, seeds, seed_r, X0, R0, cap0, ZG, zcap, zccap):
    """State of a pocket-filling packing (see sgim/rpack.py, _pack_kernel, for the loop that fills it).

    P           what is packed (PackArgs): domain box lo, hi; tol: overlap tolerance (fraction of the
                smaller radius); G: grid geometry (Grid); Dc: constraint meshes (sgim._meshq data; no
                mesh: roots of length 0); exc: excavation above-test (Exc); mode: 0 constant rconst,
                1 radius sequence rseq through a pool of pool_size, 2 graded: grade = (rf, rc, df, dc,
                spread), Dg, goff, discs = (centres, normals, radii, half thickness): the named objects;
                fseq: spread factors
    seeds       (k,3) seed positions, seed_r their radii (mode 2 recomputes them)
    X0, R0      spheres already placed (kept as they are; one zone only)
    cap0        sphere capacity (one zone: grows as needed)
    ZG          zones (see zone_of); zcap, zccap (4,): sphere and candidate room of each zone when
                parallel (fixed)
    Returns the state: spheres (Spheres), candidates (Cands), the grid's heads and block counts, the
    queues (Queue), the number of spheres given, the work arrays (Work) of two threads;
    CNT[0, 8] = 1 when the seeds do not fit a zone.
    """
    G = P.G
    nz = 4 if ZG[0] != 0.0 else 1
    grow = nz == 1

    sbase = np.zeros(nz, np.int64)
    send = np.zeros(nz, np.int64)
    cbase = np.zeros(nz, np.int64)
    cend = np.zeros(nz, np.int64)
    if nz == 1:
        send[0] = max(cap0, X0.shape[0] + 16)
        cend[0] = max(1024, 4 * seeds.shape[0] + 4096)
    else:
        for k in range(nz):
            sbase[k] = send[k - 1] if k > 0 else 0
            send[k] = sbase[k] + zcap[k]
            cbase[k] = cend[k - 1] if k > 0 else 0
            cend[k] = cbase[k] + zccap[k]
    cap = send[nz - 1]
    ccap = cend[nz - 1]
    S = Spheres(np.empty((cap, 3)), np.empty(cap),
                np.empty((cap, 4)),  # X and R side by side for the grid kernels
                np.zeros(cap), np.zeros(cap),  # bounds of the grading distance of each sphere (mode 2)
                np.full(cap, -1, np.int32),
                np.zeros((cap, 4)),  # each sphere's tangent plane on the nearest constraint surface
                np.full(cap, -1, np.int8),  # its mesh (-1: none within reach)
                np.full(cap, -1, np.int32))  # each sphere's newest queued candidate (see q_push)
    head = np.full(G.coff[-1], -1, np.int32)
    bcnt = np.zeros(G.boff[-1], np.int32)
    ZS = np.zeros((nz, 8), np.int64)
    n_initial = _place_given(P, S, head, bcnt, X0, R0)
    ZS[0, ZSN] = n_initial

    # candidates
    # a candidate in two rows: CF position and radius; CI supports (3), the number of spheres
    # when it was made, its queue links (bucket, next, previous; creator's list next, previous)
    # and its zone (9)
    C = Cands(np.empty((ccap, 4)), np.empty((ccap, 16), np.int32), np.empty((ccap, 8)), np.empty(ccap, np.int64))
    # the queue of each zone (see q_push): bucket of each candidate, links in its bucket and on its
    # creator's list
    rmax = G.rmax
    qz0 = P.lo[2] - 4.0 * rmax[-1]
    qspan = P.hi[2] - qz0 + 4.0 * rmax[-1]
    nbk = min(int(qspan / (QRES * rmax[0])) + 2, 1 << 22)
    qinv = (nbk - 2) / qspan
    bhead = np.full((nz, nbk), -1, np.int64)
    for k in range(nz):
        ZS[k, ZBM] = nbk - 1
    pool, MS = _radius_pool(P.mode, P.rseq, pool_size)
    # counters of each zone: pops, placed, pockets pushed, pop rejects, seeds placed, -, -, covered
    CNT = np.zeros((nz, 9), np.int64)
    Q = Queue(bhead, ZS, ZG, sbase, send, cbase, cend, CNT, MS, pool, qz0, qinv)
    C = _queue_seeds(seeds, seed_r, Q, C, grow, S.ohead)
    W0, W1 = _work_arrays()
    return S, C, head, bcnt, Q, n_initial, W0, W1


@njit(cache=True, error_model="numpy")
def _place_given(P, S, head, bcnt, X0, R0):
    """The spheres given beforehand into the state S: their grid cells, grading distances and tangent planes.
    Returns their number."""
    X, R, XR, DGL, DGH, nxt, FP, FPk = S.X, S.R, S.XR, S.DGL, S.DGH, S.nxt, S.FP, S.FPk
    Dc, mode, Dg, goff = P.Dc, P.mode, P.Dg, P.goff
    dcg = P.grade[3]
    dcen, dnrm, drad, dhalf = P.discs
    has_mesh = Dc[12].shape[0] > 0
    n = 0
    for i in range(X0.shape[0]):
        X[n] = X0[i]
        R[n] = R0[i]
        XR[n, 0], XR[n, 1], XR[n, 2], XR[n, 3] = X0[i, 0], X0[i, 1], X0[i, 2], R0[i]
        if mode == 2:
            DGL[n] = near_distance(Dg, goff, dcen, dnrm, drad, dhalf, X0[i, 0], X0[i, 1], X0[i, 2], dcg)
            DGH[n] = DGL[n] if DGL[n] < dcg else BIG
        grid_insert(P.G, head, nxt, bcnt, n, X[n, 0], X[n, 1], X[n, 2], R[n])
        if has_mesh:
            reach = 3.0 * R[n]
            best2 = np.inf
            for k in range(min(Dc[12].shape[0], 64)):
                if not MQ.in_root_box(Dc, k, X[n, 0], X[n, 1], X[n, 2], reach):
                    continue
                d2, qx, qy, qz, f, reg = MQ.closest_point(Dc, k, X[n, 0], X[n, 1], X[n, 2], reach * reach)
                if f >= 0 and 0.0 < d2 < best2:
                    best2 = d2
                    dd = math.sqrt(d2)
                    FP[n, 0], FP[n, 1], FP[n, 2] = (X[n, 0] - qx) / dd, (X[n, 1] - qy) / dd, (X[n, 2] - qz) / dd
                    FP[n, 3] = FP[n, 0] * qx + FP[n, 1] * qy + FP[n, 2] * qz
                    FPk[n] = k
        n += 1
    return n


@njit(cache=True)
def _radius_pool(mode, rseq, pool_size):
    """The pool of radii (mode 1), sorted descending, and MS: pooled radii, next draw, spread factors used."""
    pool = np.empty(max(pool_size, 1))
    MS = np.zeros(4, np.int64)
    if mode == 1:
        while MS[0] < pool_size and MS[1] < rseq.shape[0]:
            v = rseq[MS[1]]
            MS[1] += 1
            p = MS[0]
            while p > 0 and pool[p - 1] < v:
                pool[p] = pool[p - 1]
                p -= 1
            pool[p] = v
            MS[0] += 1
    return pool, MS


@njit(cache=True)
def _work_arrays():
    """The work arrays of two threads (Work)."""
    nbcap = 4096
    NB = np.empty((2, nbcap), np.int64)
    NBX = np.empty((2, nbcap, 3))
    NBR = np.empty((2, nbcap))
    NBH = np.empty((2, nbcap), np.int64)
    NT = np.empty((2, 6, nbcap))  # per neighbour, for the (S, A, B) pockets (see there)
    SQ = np.empty((2, 7, PCAP))
    PP = np.empty((2, 2, PCAP), np.int32)  # the pairs (A, B) of a chunk
    OUT = np.empty((2, 4, 3))
    npl_cap = 6 + 64 + 256
    PL = np.empty((2, npl_cap, 4))  # planes near the new sphere: nx ny nz h (kept side: n.x >= h)
    PLID = np.empty((2, npl_cap), np.int64)
    PLOWN = np.full((2, npl_cap), -1, np.int64)  # -1: for every neighbour; a: only for neighbour a
    return (Work(NB[0], NBX[0], NBR[0], NBH[0], NT[0], SQ[0], PP[0], OUT[0], PL[0], PLID[0], PLOWN[0]),
            Work(NB[1], NBX[1], NBR[1], NBH[1], NT[1], SQ[1], PP[1], OUT[1], PL[1], PLID[1], PLOWN[1]))


@njit(cache=True, error_model="numpy")
def _queue_seeds(seeds, seed_r, Q, C, grow, ohead):
    """Each seed as a candidate without supports, in the queue of its zone.  Returns the candidates."""
    ZS, bhead = Q.ZS, Q.bhead
    for s in range(seeds.shape[0]):
        kz = zone_of(Q.ZG, seeds[s, 0], seeds[s, 1])
        c, C = alloc_cand(kz, Q, C, grow)
        if c < 0:
            Q.CNT[0, 8] = 1
            break
        CF, CI = C.CF, C.CI
        CF[c, 0], CF[c, 1], CF[c, 2] = seeds[s, 0], seeds[s, 1], seeds[s, 2]
        CF[c, 3] = seed_r[s]
        CI[c, 3] = 0
        CI[c, 0] = SUP_NONE
        CI[c, 1] = SUP_NONE
        CI[c, 2] = SUP_NONE
        CI[c, 9] = kz
        # seeds go by the height of the floor under them (not of their centre: no sifting by
        # radius) and before the pockets at the same height
        b = q_bucket(seeds[s, 2] - seed_r[s] - 1e-9 * (abs(seeds[s, 2]) + seed_r[s]), Q.qz0, Q.qinv, bhead.shape[1])
        q_push(bhead[kz], CI, ohead, c, b, -1)
        ZS[kz, ZBM] = min(ZS[kz, ZBM], b)
        ZS[kz, ZHN] += 1
    return C


@njit(cache=True)
def lowest_bucket(ZS, bhead):
    """Lowest queued bucket over all zones (-1: none queued)."""
    lowest = -1
    for k in range(ZS.shape[0]):
        if ZS[k, ZHN] > 0:
            while bhead[k, ZS[k, ZBM]] < 0:
                ZS[k, ZBM] += 1
            if lowest < 0 or ZS[k, ZBM] < lowest:
                lowest = ZS[k, ZBM]
    return lowest


@njit(cache=True)
def pack_finish(S, Q, n_initial):
    """The packing's spheres, zone by zone, and its counters."""
    X, R, DGL = S.X, S.R, S.DGL
    ZS, sbase, CNT, MS = Q.ZS, Q.sbase, Q.CNT, Q.MS
    nz = ZS.shape[0]
    cnt = np.zeros(9, np.int64)
    for k in range(nz):
        for q in range(9):
            cnt[q] += CNT[k, q]
    cnt[5] = n_initial
    cnt[6] = MS[0]
    ntot = 0
    for k in range(nz):
        ntot += ZS[k, ZSN]
    Xo = np.empty((ntot, 3))
    Ro = np.empty(ntot)
    Do = np.empty(ntot)
    o = 0
    for k in range(nz):
        for i in range(sbase[k], sbase[k] + ZS[k, ZSN]):
            Xo[o, 0], Xo[o, 1], Xo[o, 2] = X[i, 0], X[i, 1], X[i, 2]
            Ro[o] = R[i]
            Do[o] = DGL[i]
            o += 1
    return Xo, Ro, Do, cnt
