"""Numba kernels: random dense packing by pocket filling, and packing statistics.

Algorithm (see sgim/rpack.py for the user-facing description)
------------------------------------------------------------
A *pocket* is a position where a new sphere of radius r touches three supports at once:
three spheres, two spheres and a plane, or one sphere and two planes.  Planes are the six
walls of the domain box and the tangent planes of the constraint surfaces (excavation
surfaces, cavities, the fill shape) at the foot of the closest point.  After each sphere is
placed, every pocket it forms with its neighbours is computed in closed form, checked, and
queued by its height z.  The lowest pocket is taken and filled.  Seeds (sphere positions on
the floor of the region) start the process; it ends when no pocket is left.

The queue is a bucket queue: buckets QRES x the smallest grid level's largest radius high,
each a list taken newest first (the pockets made by the last spheres placed, which are still
in the cache; within a bucket the order is not by height).  A queued pocket is removed as soon as a new sphere covers
it: the pocket touches the sphere that made it, so a sphere that covers it lies within
r + r_maker + 2 r_pocket of its maker, a neighbour the new sphere gathers anyway; each sphere
keeps the list of its queued pockets.  For a constant radius this is complete and a pocket
taken from the queue needs no further check; with a radius law or a grading the pocket may be
filled by another radius than it was made for, and it is checked again against the spheres
placed since it was made.

Every placed sphere touches its supports exactly (up to rounding), so the overlap is zero up
to the stated tolerance and spheres touch the walls and surfaces they rest on.

A position P for a sphere of radius r is *admissible* when
  * it overlaps no placed sphere j by more than ``tol * min(r, r_j)``;
  * it lies in the box shrunk by r (allowance ``tol * r``);
  * its distance to every constraint surface is at least ``r (1 - tol)``;
  * it is not above an excavation surface in vertical projection (the exact rule).
The side of closed surfaces is not tested for pockets: a pocket touches an admissible sphere,
and a path of length r_S + r from an admissible centre cannot cross a surface while keeping
both ends at distance >= r_S and >= r from it (seeds are tested in full by the caller).

Radius modes: 0 constant radius; 1 a radius law given as a pre-drawn sequence, placed through
a small pool (each pocket takes the largest pooled radius that fits: the placed radii are the
drawn sequence minus what is left in the pool at the end); 2 graded: the radius is a function
of the distance to named objects (sgim/grading.py), times an optional spread factor from a
pre-drawn sequence.

Neighbour search: a multi-level grid of linked lists (level k holds radii in
[r0 2^k, r0 2^(k+1)), cell 2 x the level's largest radius), with block counts so that a large
query over a fine level skips empty space.

Modules: this one holds the loop (fill) and its steps; sgim/_rpgrid.py the grid, sgim/_rppocket.py the
closed-form pockets, sgim/_rpregion.py the region and the grading distance, sgim/_rpstate.py the queue,
zones and the state (pack_init, pack_finish), sgim/_rpprobe.py the statistics' clearance probes.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _meshq as MQ
from ._rpgrid import grid_gather, grid_insert, grid_overlaps
from ._rppocket import SUP_NONE, SUP_PLANE0, clear_of, pocket_spp, pocket_ssp, refine, reposition
from ._rpregion import above_excavation, grade_radius, in_box, near_distance, region_ok
from ._rpstate import (BIG, PCAP, ST_DONE, ST_FULL, ST_PAUSE, ZBM, ZHN, ZSN, Spheres, _grow1, _grow2, free_cand,
                       push_pocket, q_remove)

DEEP = 0.5  # see the pair loop of _pockets_sab()
PAD = 8  # vector length the neighbour loops are padded to

# fill's steps (_choose, _place, _neighbours, _near_planes, _pockets_sab, _pockets_planes) are inlined into it
# (inline="always"): one function as before, without a call (and the arrays' reference counts) per sphere


@njit(cache=True, error_model="numpy", nogil=True)
def fill(z0, z1, bz, budget, grow, P, S, C, head, bcnt, Q, W):
    """Fill the pockets of zones z0..z1 below bucket bz, lowest first, for at most budget spheres.
    P: what is packed (PackArgs); S: spheres (Spheres), C: candidates (Cands), head, bcnt: the grid's
    lists, Q: queues and zones (Queue), W: this thread's work arrays (Work); see sgim/_rpstate.py.
    Returns (status, S, C), grown when grow."""
    mode, rconst, grade = P.mode, P.rconst, P.grade
    ZS, bhead, MS, pool = Q.ZS, Q.bhead, Q.MS, Q.pool
    cnt = Q.CNT[z0]
    npool, iseq, ifac = MS[0], MS[1], MS[2]
    pdl, pdh = 0.0, 0.0
    stop = cnt[1] + budget
    status = ST_DONE
    while True:
        if cnt[1] >= stop:
            status = ST_PAUSE
            break
        kp = -1
        bb = bz
        for k in range(z0, z1 + 1):
            if ZS[k, ZHN] > 0:
                bm = ZS[k, ZBM]
                while bhead[k, bm] < 0:
                    bm += 1
                ZS[k, ZBM] = bm
                if bm < bb:
                    bb = bm
                    kp = k
        if kp < 0:
            break
        c = bhead[kp, bb]
        q_remove(bhead[kp], C.CI, S.ohead, c, C.CI[c, 0])
        ZS[kp, ZHN] -= 1
        free_cand(c, Q, C.CI, C.freel)
        cnt[0] += 1
        seed = C.CI[c, 0] == SUP_NONE
        placed, px, py, pz, rr, pdl, pdh, npool, iseq = _choose(P, S, C, head, bcnt, pool, c, npool, iseq, ifac,
                                                                pdl, pdh, W.OUT[0:2])
        if not placed:
            cnt[3] += 1
            continue
        # --- place ---------------------------------------------------------------
        i = Q.sbase[kp] + ZS[kp, ZSN]
        if i == Q.send[kp]:
            if not grow:
                return ST_FULL, S, C
            S = _grow_spheres(S)
            Q.send[kp] = S.X.shape[0]
        ZS[kp, ZSN] += 1
        if mode == 2:
            if not seed:
                ifac += 1
            if seed:
                dcen, dnrm, drad, dhalf = P.discs
                pdl = near_distance(P.Dg, P.goff, dcen, dnrm, drad, dhalf, px, py, pz, grade[3])
                pdh = pdl if pdl < grade[3] else BIG
        _place(P, S, head, bcnt, i, px, py, pz, rr, pdl, pdh)
        cnt[1] += 1
        if seed:
            cnt[4] += 1

        # --- new pockets ---------------------------------------------------------
        if mode == 0:
            rn = rconst
        elif mode == 1:
            if npool == 0:
                continue
            rn = pool[npool - 1]
        else:
            rn = grade_radius(S.DGL[i], grade[0], grade[1], grade[2], grade[3]) * (1.0 - grade[4])
        m = _neighbours(P, S, C, head, bcnt, Q, W, i, px, py, pz, rr, rn, cnt)
        npl = _near_planes(P, S, W, i, px, py, pz, rr, rn, m)
        ok, C = _pockets_sab(P, C, Q, W, i, px, py, pz, rr, rn, m, grow, S.ohead, cnt)
        if not ok:
            return ST_FULL, S, C
        ok, C = _pockets_planes(P, C, Q, W, i, px, py, pz, rr, rn, m, npl, grow, S.ohead, cnt)
        if not ok:
            return ST_FULL, S, C
    if grow:  # one zone (a radius law or a grading: their pool and draws are sequential)
        MS[0], MS[1], MS[2] = npool, iseq, ifac
    return status, S, C


@njit(cache=True, error_model="numpy")
def _grow_spheres(S):
    """The spheres' arrays half as large again (one zone: its range is the whole array)."""
    cap = S.X.shape[0] + S.X.shape[0] // 2 + 16
    return Spheres(_grow2(S.X, cap), _grow1(S.R, cap, 0.0), _grow2(S.XR, cap), _grow1(S.DGL, cap, 0.0),
                   _grow1(S.DGH, cap, 0.0), _grow1(S.nxt, cap, -1), _grow2(S.FP, cap), _grow1(S.FPk, cap, -1),
                   _grow1(S.ohead, cap, -1))


@njit(cache=True, error_model="numpy", inline="always")
def _place(P, S, head, bcnt, i, px, py, pz, rr, pdl, pdh):
    """Sphere i at P with radius rr (grading distance bounds pdl, pdh) into the arrays and the grid."""
    S.X[i, 0], S.X[i, 1], S.X[i, 2] = px, py, pz
    S.R[i] = rr
    S.XR[i, 0], S.XR[i, 1], S.XR[i, 2], S.XR[i, 3] = px, py, pz, rr
    if P.mode == 2:
        dcg = P.grade[3]
        S.DGL[i], S.DGH[i] = pdl, (pdh if pdh < dcg else BIG)
    grid_insert(P.G, head, S.nxt, bcnt, i, px, py, pz, rr)


@njit(cache=True, error_model="numpy", inline="always")
def _choose(P, S, C, head, bcnt, pool, c, npool, iseq, ifac, pdl, pdh, out):
    """The radius and exact position for popped candidate c (a pooled radius that fits, mode 1; the
    grading law's fixed point, mode 2) and whether it can be placed.  Takes a radius from the pool
    when placed.  Returns (placed, px, py, pz, r, grading distance bounds, pooled radii, next draw)."""
    lo, hi, tol, Dc, exc, mode, rseq, fseq = P.lo, P.hi, P.tol, P.Dc, P.exc, P.mode, P.rseq, P.fseq
    rf, rc, df, dcg, spread = P.grade
    dcen, dnrm, drad, dhalf = P.discs
    X, R, XR, DGL, DGH, nxt = S.X, S.R, S.XR, S.DGL, S.DGH, S.nxt
    CF, CI, cpl = C.CF, C.CI, C.cpl
    has_mesh = Dc[12].shape[0] > 0
    check_region = has_mesh or exc.gnx > 0
    r0 = CF[c, 3]
    px, py, pz = 0.0, 0.0, 0.0
    placed = False
    rr = r0
    seed = CI[c, 0] == SUP_NONE
    if mode != 0 and not seed:
        # a pocket that the spheres placed since it was made fill for its own radius is gone
        # for the others too (most pops end here, without trying other radii)
        if grid_overlaps(P.G, head, nxt, bcnt, XR, CF[c, 0], CF[c, 1], CF[c, 2], r0, tol, CI[c, 3]):
            return False, px, py, pz, rr, pdl, pdh, npool, iseq
    ntry = npool if (mode == 1 and not seed) else 1
    for t in range(ntry):
        px, py, pz = CF[c, 0], CF[c, 1], CF[c, 2]
        if mode == 0 or seed:
            rr = r0  # seeds keep the radius they were made with
        elif mode == 1:
            rr = pool[t]
            if rr != r0:
                if not reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                    continue
                px, py, pz = out[0, 0], out[0, 1], out[0, 2]
        else:
            fac = fseq[ifac % fseq.shape[0]] if fseq.shape[0] > 0 else 1.0
            rr = r0
            # the distance is 1-Lipschitz: from the creating sphere's bounds, |P - S| <= R_S + rmax
            sS = CI[c, 0]
            dlo, dhi = -1.0, BIG
            if sS >= 0:
                dlo = DGL[sS] - (R[sS] + rc * (1.0 + spread))
                dhi = DGH[sS] + R[sS] + rc * (1.0 + spread)
            if dlo >= dcg or dhi <= df:
                rnew = (rc if dlo >= dcg else rf) * fac
                if rnew != rr:
                    rr = rnew
                    if not reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                        break
                    px, py, pz = out[0, 0], out[0, 1], out[0, 2]
                pdl, pdh = max(dlo, 0.0), dhi
            else:
                # fixed point r = law(d(P(r))) * factor, damped after a few rounds; a pocket
                # where it does not settle is dropped (its radius would not follow the law)
                conv = False
                for it in range(40):
                    d = near_distance(P.Dg, P.goff, dcen, dnrm, drad, dhalf, px, py, pz, dcg)
                    pdl, pdh = d, d
                    rnew = grade_radius(d, rf, rc, df, dcg) * fac
                    if abs(rnew - rr) <= 1e-12 * rnew:
                        conv = True
                        break
                    rr = rnew if it < 10 else rr + 0.5 * (rnew - rr)
                    if not reposition(CI, cpl, c, X, R, lo, hi, rr, CF, out):
                        break
                    px, py, pz = out[0, 0], out[0, 1], out[0, 2]
                if not conv:
                    break
        moved = rr != r0
        if moved or CI[c, 0] == SUP_NONE:
            if not in_box(lo, hi, px, py, pz, rr, tol):
                continue
            if check_region and not region_ok(px, py, pz, rr, tol, has_mesh, Dc, exc):
                continue
        stamp = 0 if moved else CI[c, 3]
        # a constant-radius pocket still queued is clear: the spheres placed since it was made
        # removed it if they covered it (see the covering step in _neighbours)
        if not (mode == 0 and not seed) and grid_overlaps(P.G, head, nxt, bcnt, XR, px, py, pz, rr, tol, stamp):
            continue
        placed = True
        if mode == 1 and not seed:
            for q in range(t, npool - 1):
                pool[q] = pool[q + 1]
            npool -= 1
            if iseq < rseq.shape[0]:
                v = rseq[iseq]
                iseq += 1
                p = npool
                while p > 0 and pool[p - 1] < v:
                    pool[p] = pool[p - 1]
                    p -= 1
                pool[p] = v
                npool += 1
        break
    return placed, px, py, pz, rr, pdl, pdh, npool, iseq


@njit(cache=True, error_model="numpy", inline="always")
def _neighbours(P, S, C, head, bcnt, Q, W, i, px, py, pz, rr, rn, cnt):
    """The neighbours of new sphere i (within rr + 2 rn) into W.nb, the nearest first, with their centres and
    radii (W.nbx, W.nbr); the queued pockets the sphere covers removed.  Returns their number."""
    nb, nbx, nbr = W.nb, W.nbx, W.nbr
    XR, ohead = S.XR, S.ohead
    CF, CI = C.CF, C.CI
    tol = P.tol
    m = grid_gather(P.G, head, S.nxt, bcnt, XR, px, py, pz, rr + 2.0 * rn, nb, nb.shape[0], i)
    # remove the queued pockets the new sphere covers.  A pocket Q of radius rq made by sphere
    # j touches it (|Q - x_j| = r_j + rq); covered, |Q - P| < rr + rq, so |P - x_j| < rr + r_j + 2 rq:
    # j is among the neighbours gathered when rq <= rn (always for a constant radius)
    for a in range(m):
        c2 = ohead[nb[a]]
        while c2 >= 0:
            c3 = CI[c2, 7]
            rq = CF[c2, 3]
            dx = CF[c2, 0] - px
            dy = CF[c2, 1] - py
            dz = CF[c2, 2] - pz
            lim = rq + rr - tol * min(rq, rr)
            if dx * dx + dy * dy + dz * dz < lim * lim:
                kq = CI[c2, 9]
                q_remove(Q.bhead[kq], CI, ohead, c2, nb[a])
                Q.ZS[kq, ZHN] -= 1
                free_cand(c2, Q, CI, C.freel)
                cnt[7] += 1
            c2 = c3
    # the nearest neighbour first: it excludes the most pocket directions (tried before the others)
    best = BIG
    ab = 0
    for a in range(m):
        j = nb[a]
        dj = (XR[j, 0] - px) ** 2 + (XR[j, 1] - py) ** 2 + (XR[j, 2] - pz) ** 2 - (XR[j, 3] + rr) ** 2
        if dj < best:
            best = dj
            ab = a
    if m > 0:
        j = nb[ab]
        nb[ab] = nb[0]
        nb[0] = j
    for a in range(m):
        j = nb[a]
        nbx[a, 0], nbx[a, 1], nbx[a, 2] = XR[j, 0], XR[j, 1], XR[j, 2]
        nbr[a] = XR[j, 3]
    return m


@njit(cache=True, error_model="numpy", inline="always")
def _near_planes(P, S, W, i, px, py, pz, rr, rn, m):
    """The planes near new sphere i into W.pl (walls within rr + 2 rn, the tangent planes of the constraint
    surfaces at its own foot points and at its m neighbours'); its own nearest tangent plane into S.FP.
    Returns their number."""
    lo, hi, Dc = P.lo, P.hi, P.Dc
    X, FP, FPk = S.X, S.FP, S.FPk
    nb, pl, plid, plown = W.nb, W.pl, W.plid, W.plown
    npl = 0
    for w in range(6):
        ax = w // 2
        if w % 2 == 0:
            hgt = X[i, ax] - lo[ax]
        else:
            hgt = hi[ax] - X[i, ax]
        if hgt < rr + 2.0 * rn:
            pl[npl, 0], pl[npl, 1], pl[npl, 2] = 0.0, 0.0, 0.0
            if w % 2 == 0:
                pl[npl, ax] = 1.0
                pl[npl, 3] = lo[ax]
            else:
                pl[npl, ax] = -1.0
                pl[npl, 3] = -hi[ax]
            plid[npl] = -1 - w
            npl += 1
    for p in range(npl):
        plown[p] = -1
    if Dc[12].shape[0] > 0:
        reach = rr + 2.0 * rn
        best2 = np.inf
        for k in range(min(Dc[12].shape[0], 64)):
            if not MQ.in_root_box(Dc, k, px, py, pz, reach):
                continue
            d2, qx, qy, qz, f, reg = MQ.closest_point(Dc, k, px, py, pz, reach * reach)
            if f < 0 or d2 <= 0.0:
                continue
            dd = math.sqrt(d2)
            pl[npl, 0], pl[npl, 1], pl[npl, 2] = (px - qx) / dd, (py - qy) / dd, (pz - qz) / dd
            pl[npl, 3] = pl[npl, 0] * qx + pl[npl, 1] * qy + pl[npl, 2] * qz
            plid[npl] = SUP_PLANE0
            plown[npl] = -1
            if d2 < best2:  # the sphere's own tangent plane, for the pockets of later neighbours
                best2 = d2
                FP[i, 0], FP[i, 1], FP[i, 2], FP[i, 3] = pl[npl, 0], pl[npl, 1], pl[npl, 2], pl[npl, 3]
                FPk[i] = k
            npl += 1
        # the tangent planes of the neighbours (a curved or kinked surface: the pocket touching S,
        # A and the surface may rest on the part of the surface nearest to A, not to S)
        npl0 = npl
        for a in range(m):
            ja = nb[a]
            if FPk[ja] < 0 or npl == pl.shape[0]:
                continue
            same = False
            for p in range(npl0):
                if plid[p] == SUP_PLANE0 and pl[p, 0] * FP[ja, 0] + pl[p, 1] * FP[ja, 1] + pl[p, 2] * FP[ja, 2] \
                        > 1.0 - 1e-9 and abs(pl[p, 3] - FP[ja, 3]) <= 1e-9 * (1.0 + abs(FP[ja, 3])):
                    same = True
            if same or FP[ja, 0] * px + FP[ja, 1] * py + FP[ja, 2] * pz - FP[ja, 3] >= rr + 2.0 * rn:
                continue
            pl[npl, 0], pl[npl, 1], pl[npl, 2], pl[npl, 3] = FP[ja, 0], FP[ja, 1], FP[ja, 2], FP[ja, 3]
            plid[npl] = SUP_PLANE0
            plown[npl] = a
            npl += 1
    return npl


@njit(cache=True, error_model="numpy", inline="always")
def _pockets_sab(P, C, Q, W, i, px, py, pz, rr, rn, m, grow, ohead, cnt):
    """Queue the pockets of radius rn touching new sphere i (at P, radius rr) and two of its m neighbours
    A, B (W.nb, the nearest first).  Returns (False when a zone is full, the candidates C)."""
    lo, hi, tol, Dc, exc = P.lo, P.hi, P.tol, P.Dc, P.exc
    nb, nbx, nbr, nbh, NT, SQ, PP = W.nb, W.nbx, W.nbr, W.nbh, W.NT, W.SQ, W.PP
    nU, nV, nW, nUU, nKU, nL2 = NT[0], NT[1], NT[2], NT[3], NT[4], NT[5]
    PA, PB = PP[0], PP[1]
    has_mesh = Dc[12].shape[0] > 0
    check_region = has_mesh or exc.gnx > 0
    tiny_tol = tol < 1e-9
    zcut = pz - DEEP * (rr + rn)
    # per neighbour (structure of arrays): position relative to S, |.|^2, the term of the
    # pocket solve that depends on one neighbour only, the squared clearance limit for rn
    ds = rr + rn
    ds2 = ds * ds
    for a in range(m):
        ua, va, wa = nbx[a, 0] - px, nbx[a, 1] - py, nbx[a, 2] - pz
        nU[a], nV[a], nW[a] = ua, va, wa
        uua = ua * ua + va * va + wa * wa
        nUU[a] = uua
        dba = nbr[a] + rn
        nKU[a] = 0.5 * (ds2 + uua - dba * dba)
        lm = rn + nbr[a] - tol * min(rn, nbr[a])
        nL2[a] = lm * lm
    # the box shrunk by rn (allowance tol rn), relative to S
    bxlo, bxhi = lo[0] + rn - tol * rn - px, hi[0] - rn + tol * rn - px
    bylo, byhi = lo[1] + rn - tol * rn - py, hi[1] - rn + tol * rn - py
    bzlo, bzhi = lo[2] + rn - tol * rn - pz, hi[2] - rn + tol * rn - pz
    # neighbours above zcut, in order: a neighbour below it pairs only with these
    nhigh = 0
    for a in range(m):
        nbh[nhigh] = a
        nhigh += nW[a] + pz >= zcut
    # pad the neighbour terms to a multiple of PAD with far-away dummies (the clearance loop
    # below then runs whole vector lengths, no remainder)
    mp = min((m + PAD - 1) // PAD * PAD, nb.shape[0])
    for e in range(m, mp):
        nU[e], nV[e], nW[e], nL2[e] = 1e100, 0.0, 0.0, 0.0
    # the pairs (A, B), A < B, within reach of each other, in chunks of at most PCAP: first
    # listed without a branch, then solved in one loop, then checked
    hp = 0  # nbh[hp:] are the neighbours above zcut with an index > a
    a0 = 0
    while a0 < m:
        npb = 0
        while a0 < m and npb + m - a0 <= PCAP:
            a = a0
            a0 += 1
            while hp < nhigh and nbh[hp] <= a:
                hp += 1
            ux, uy, uz = nU[a], nV[a], nW[a]
            ra2 = nbr[a] + 2.0 * rn
            alow = uz + pz < zcut
            nbt = (nhigh - hp) if alow else (m - a - 1)
            for t in range(nbt):
                b = nbh[hp + t] if alow else a + 1 + t
                lim = ra2 + nbr[b]
                PA[npb] = a
                PB[npb] = b
                npb += (ux - nU[b]) ** 2 + (uy - nV[b]) ** 2 + (uz - nW[b]) ** 2 < lim * lim
        for t in range(npb, (npb + PAD - 1) // PAD * PAD):
            PA[t] = 0  # A = B: no pocket
            PB[t] = 0
        # the pockets |Q| = ds, |Q - A| = ra + rn, |Q - B| = rb + rn (Q relative to S):
        # Q = al A + be B +- g (A x B); none (g < 0) where g2 < 0 or A, B are aligned with S
        for t in range((npb + PAD - 1) // PAD * PAD):
            a = PA[t]
            b = PB[t]
            ux, uy, uz, uu, ku = nU[a], nV[a], nW[a], nUU[a], nKU[a]
            vx, vy, vz, vv, kv = nU[b], nV[b], nW[b], nUU[b], nKU[b]
            uv = ux * vx + uy * vy + uz * vz
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            det = nx * nx + ny * ny + nz * nz
            idet = 1.0 / max(det, 1e-300)
            al = (ku * vv - kv * uv) * idet
            be = (kv * uu - ku * uv) * idet
            g2 = (ds2 - al * ku - be * kv) * idet
            gg = math.sqrt(max(g2, 0.0))
            g = gg if ((det > 1e-12 * uu * vv) & (g2 >= 0.0)) else -1.0
            SQ[0, t] = al * ux + be * vx
            SQ[1, t] = al * uy + be * vy
            SQ[2, t] = al * uz + be * vz
            SQ[3, t] = g * nx
            SQ[4, t] = g * ny
            SQ[5, t] = g * nz
            SQ[6, t] = g
        for t in range(npb):
            if SQ[6, t] < 0.0:
                continue
            a = PA[t]
            b = PB[t]
            for q in range(2):
                if q == 0:
                    qx, qy, qz = SQ[0, t] + SQ[3, t], SQ[1, t] + SQ[4, t], SQ[2, t] + SQ[5, t]
                else:
                    qx, qy, qz = SQ[0, t] - SQ[3, t], SQ[1, t] - SQ[4, t], SQ[2, t] - SQ[5, t]
                if not (bxlo <= qx <= bxhi and bylo <= qy <= byhi and bzlo <= qz <= bzhi):
                    continue
                # clear of every neighbour: the nearest first, then all of them without a branch
                # (A and B touch Q, tol min(r) beyond the limit: they never count unless tol is
                # near the rounding error, where they are left out by name)
                if not tiny_tol and (nU[0] - qx) ** 2 + (nV[0] - qy) ** 2 + (nW[0] - qz) ** 2 < nL2[0]:
                    continue
                nblk = 0
                for e in range(mp):
                    dx = nU[e] - qx
                    dy = nV[e] - qy
                    dz = nW[e] - qz
                    nblk += dx * dx + dy * dy + dz * dz < nL2[e]
                if nblk > 0 and tiny_tol:
                    nblk = 0
                    for e in range(m):
                        if e != a and e != b and (nU[e] - qx) ** 2 + (nV[e] - qy) ** 2 + (nW[e] - qz) ** 2 < nL2[e]:
                            nblk += 1
                if nblk > 0:
                    continue
                qx, qy, qz = qx + px, qy + py, qz + pz
                if check_region and not region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, exc):
                    continue
                cc, C = push_pocket((qx, qy, qz), rn, i, nb[a], nb[b], (0.0, 0.0, 0.0, 0.0), Q, C, grow, ohead, cnt)
                if cc < 0:
                    return False, C
    return True, C


@njit(cache=True, error_model="numpy", inline="always")
def _pockets_planes(P, C, Q, W, i, px, py, pz, rr, rn, m, npl, grow, ohead, cnt):
    """Queue the pockets of radius rn touching new sphere i (at P, radius rr), one of its m neighbours and one
    of the npl planes near it (W.pl), or two of the planes.  Returns (False when a zone is full, the
    candidates C)."""
    lo, hi, tol, Dc, exc = P.lo, P.hi, P.tol, P.Dc, P.exc
    nb, nbx, nbr, pl, plid, plown = W.nb, W.nbx, W.nbr, W.pl, W.plid, W.plown
    out, out2 = W.OUT[0:2], W.OUT[2:4]
    has_mesh = Dc[12].shape[0] > 0
    check_region = has_mesh or exc.gnx > 0
    for p in range(npl):
        nx_, ny_, nz_, h0 = pl[p, 0], pl[p, 1], pl[p, 2], pl[p, 3]
        for a in range(m):
            if plown[p] >= 0 and plown[p] != a:
                continue
            ax_, ay_, az_, ra = nbx[a, 0], nbx[a, 1], nbx[a, 2], nbr[a]
            if nx_ * ax_ + ny_ * ay_ + nz_ * az_ - h0 >= ra + 2.0 * rn:
                continue
            k2 = pocket_ssp(px, py, pz, rr + rn, ax_, ay_, az_, ra + rn, nx_, ny_, nz_, h0 + rn, out)
            for q in range(k2):
                qx, qy, qz = out[q, 0], out[q, 1], out[q, 2]
                if not (in_box(lo, hi, qx, qy, qz, rn, tol) and clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, -1)):
                    continue
                snx, sny, snz, sh = nx_, ny_, nz_, h0
                if check_region and not region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, exc):
                    if plid[p] != SUP_PLANE0:
                        continue
                    ok, qx, qy, qz, snx, sny, snz, sh = refine(0, (px, py, pz, rr + rn), (ax_, ay_, az_, ra + rn),
                                                               (0.0, 0.0, 0.0, 0.0), (nx_, ny_, nz_, h0), rn, tol,
                                                               (qx, qy, qz), Dc, out2)
                    if not ok or not (in_box(lo, hi, qx, qy, qz, rn, tol)
                                      and clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, a, -1)):
                        continue
                    if exc.gnx > 0 and above_excavation(exc, qx, qy, qz):
                        continue
                cc, C = push_pocket((qx, qy, qz), rn, i, nb[a], plid[p], (snx, sny, snz, sh), Q, C, grow, ohead, cnt)
                if cc < 0:
                    return False, C
        for p2 in range(p + 1, npl):
            if (plid[p] == SUP_PLANE0 and plid[p2] == SUP_PLANE0) or plown[p] >= 0 or plown[p2] >= 0:
                continue
            mx_, my_, mz_, h1 = pl[p2, 0], pl[p2, 1], pl[p2, 2], pl[p2, 3]
            k2 = pocket_spp(px, py, pz, rr + rn, nx_, ny_, nz_, h0 + rn, mx_, my_, mz_, h1 + rn, out)
            sp = p if plid[p] == SUP_PLANE0 else p2  # the surface plane, if any
            for q in range(k2):
                qx, qy, qz = out[q, 0], out[q, 1], out[q, 2]
                if not (in_box(lo, hi, qx, qy, qz, rn, tol) and clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, -1, -1)):
                    continue
                snx, sny, snz, sh = pl[sp, 0], pl[sp, 1], pl[sp, 2], pl[sp, 3]
                if check_region and not region_ok(qx, qy, qz, rn, tol, has_mesh, Dc, exc):
                    if plid[sp] != SUP_PLANE0:
                        continue
                    wp = p2 if sp == p else p
                    ok, qx, qy, qz, snx, sny, snz, sh = refine(1, (px, py, pz, rr + rn), (0.0, 0.0, 0.0, 0.0),
                                                               (pl[wp, 0], pl[wp, 1], pl[wp, 2], pl[wp, 3] + rn),
                                                               (snx, sny, snz, sh), rn, tol, (qx, qy, qz), Dc, out2)
                    if not ok or not (in_box(lo, hi, qx, qy, qz, rn, tol)
                                      and clear_of(qx, qy, qz, rn, tol, nbx, nbr, m, -1, -1)):
                        continue
                    if exc.gnx > 0 and above_excavation(exc, qx, qy, qz):
                        continue
                # a wall first, then the other support (a wall or the stored plane)
                w1, w2 = plid[p], plid[p2]
                if w1 == SUP_PLANE0:
                    w1, w2 = w2, w1
                cc, C = push_pocket((qx, qy, qz), rn, i, w1, w2, (snx, sny, snz, sh), Q, C, grow, ohead, cnt)
                if cc < 0:
                    return False, C
    return True, C
