"""Mitsuba 3's ray traversal alone on mitsuba_compare.sh's box (run by
bench/mitsuba_trace.sh beside camsim's `packet_timing_cornell_box`).

The rays are drawn as camsim's timing test draws them (its own generator, so
the same distribution, not the same rays): a point uniform in [-0.9, 0.9]^3
and a uniform direction give a landing point on the box; from there (offset
1e-4 along the normal turned towards the incoming side) one cosine-weighted
bounce ray, and one shadow ray to a uniform point of the light's rectangle
(x in ±0.23, y = 0.99, z in 0.01 ± 0.19) ending 1e-4 short of it. Timed
(least of 5, to kernel completion with dr.sync_thread()):
`scene.ray_intersect_preliminary` (t and primitive, what a closest-hit query
returns) and `scene.ray_test` (occlusion), once in the order drawn and once
sorted by direction octant and then origin cell of a 4 x 4 x 4 grid over
[-1, 1]^3, the key of camsim's `sorted_by_cell`.
"""
import argparse
import time

import numpy as np
import mitsuba as mi
import drjit as dr

from mitsuba_compare import machine_cpu, machine_simd_flags


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--rays", type=int, default=1 << 18,
                    help="bounce (and shadow) rays; 2^18 as camsim's timing test (its sorted groups are as coherent)")
    a = ap.parse_args()
    variant = "llvm_ad_spectral"
    mi.set_variant(variant)
    dr.set_thread_count(a.threads)
    scene = mi.load_dict(mi.cornell_box())
    rng = np.random.default_rng(11)
    n = int(a.rays * 1.25)  # about 85 % of the random rays land
    o = rng.uniform(-0.9, 0.9, (n, 3)).astype(np.float32)
    z = rng.uniform(-1, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T)))
    p, nrm = np.array(si.p), np.array(si.n)
    if p.shape[0] == 3 and p.shape[1] != 3:
        p, nrm = p.T.copy(), nrm.T.copy()
    ok = np.array(si.is_valid())
    p, nrm, d = p[ok][: a.rays], nrm[ok][: a.rays], d[ok][: a.rays]
    flip = (nrm * d).sum(1) > 0
    nrm[flip] = -nrm[flip]
    m = len(p)
    u1, u2 = rng.uniform(size=m), rng.uniform(size=m)
    rr, ph = np.sqrt(u1), 2 * np.pi * u2
    lx, ly, lz = rr * np.cos(ph), rr * np.sin(ph), np.sqrt(np.maximum(0, 1 - u1))
    helper = np.where(np.abs(nrm[:, 0:1]) > 0.9, np.array([[0, 1, 0]]), np.array([[1, 0, 0]]))
    s = np.cross(nrm, helper)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    t = np.cross(nrm, s)
    wi = (s * lx[:, None] + t * ly[:, None] + nrm * lz[:, None]).astype(np.float32)
    po = (p + nrm * 1e-4).astype(np.float32)
    q = np.stack([rng.uniform(-0.23, 0.23, m), np.full(m, 0.99), 0.01 + rng.uniform(-0.19, 0.19, m)], 1)
    sd = q.astype(np.float32) - po
    length = np.linalg.norm(sd, axis=1)
    sd = (sd / length[:, None]).astype(np.float32)
    smax = (length * (1 - 1e-4)).astype(np.float32)

    def key(orig, dirs):
        cell = np.clip(((orig + 1.0) * 2).astype(int), 0, 3)
        octant = (dirs[:, 0] < 0) * 1 + (dirs[:, 1] < 0) * 2 + (dirs[:, 2] < 0) * 4
        return octant * 64 + cell[:, 0] * 16 + cell[:, 1] * 4 + cell[:, 2]

    def timed(f):
        best = float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            f()
            dr.sync_thread()
            best = min(best, time.perf_counter() - t0)
        return best

    print(f"CPU {machine_cpu()}; SIMD flags: {machine_simd_flags()}")
    print(f"Mitsuba {mi.__version__} {variant}, {a.threads} thread(s), {m} bounce and {m} shadow rays")
    for order in ("as drawn", "sorted by octant and origin cell"):
        kb = np.argsort(key(po, wi), kind="stable") if order != "as drawn" else np.arange(m)
        ks = np.argsort(key(po, sd), kind="stable") if order != "as drawn" else np.arange(m)
        bounce = mi.Ray3f(mi.Point3f(*po[kb].T), mi.Vector3f(*wi[kb].T))
        shadow = mi.Ray3f(mi.Point3f(*po[ks].T), mi.Vector3f(*sd[ks].T))
        shadow.maxt = mi.Float(smax[ks])
        dr.eval(bounce, shadow)
        dr.sync_thread()

        def closest():
            pi = scene.ray_intersect_preliminary(bounce)
            dr.eval(pi.t, pi.prim_index)

        def occluded():
            dr.eval(scene.ray_test(shadow))

        tc, to = timed(closest), timed(occluded)
        hit = np.array(dr.isfinite(scene.ray_intersect_preliminary(bounce).t)).mean()
        blocked = np.array(scene.ray_test(shadow)).mean()
        print(f"  rays {order}: closest {tc * 1e9 / m:.1f} ns/ray ({hit:.3f} hit), "
              f"occlusion {to * 1e9 / m:.1f} ns/ray ({blocked:.3f} blocked)")


if __name__ == "__main__":
    main()
