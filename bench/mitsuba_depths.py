"""Where a path's time goes, bounce by bounce: camsim and Mitsuba 3 on the
scene of mitsuba_compare.py (Mitsuba's cornell_box(), 256×256, box filter,
2 threads) with the bounce limit raised one step at a time.

Mitsuba's max_depth d is camsim's max_bounces d − 1: d = 1 is the camera's
rays and what they see directly (sampler, camera, one closest hit, emission,
film); d = 2 adds the first bounce (a next-event shadow ray, a BSDF sample and
its ray), and so on. The time each step adds is the cost of that bounce for
the paths that reach it. Neither renderer plays Russian roulette before its
second bounce, so the steps to d = 1 and 2 compare like with like; camsim
plays it from its second bounce on (its step to d = 3 already saves rays),
Mitsuba from depth 5 (rr_depth), and the step to d = 7 shows what the two
roulettes save.

Each time is the least of --repeats renders (Mitsuba after a warm-up render
that compiles its kernel, timed to completion with dr.sync_thread(); camsim's
`bench render` wall time of the render alone). Prints a table and one line
  DEPTHS camsim/Mitsuba time: d=1 …, d=2 …, …; CPU <model> (<vector width>), load …
"""

import argparse
import os
import time

import mitsuba_compare as mc


def camsim_s(camsim, spp, max_bounces, seed, threads):
    """camsim's render wall time (s) at this bounce limit."""
    kv = mc.camsim_bench(camsim, ["--spp", str(spp), "--batches", "1", "--threads", str(threads),
                                  "--seed", str(seed), "--max-bounces", str(max_bounces)])
    if int(kv.get("max_bounces", -1)) != max_bounces:
        raise SystemExit(f"camsim did not render at max_bounces {max_bounces}: {kv}")
    return float(kv["wall_s"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--camsim", required=True)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--depths", default="1,2,3,4,7", help="Mitsuba max_depth values (camsim: one less)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--mitsuba-isa", default="native", choices=sorted(mc.MITSUBA_ISAS),
                    help="what Dr.Jit compiles Mitsuba's kernels for (as mitsuba_compare.py)")
    a = ap.parse_args()
    depths = [int(x) for x in a.depths.split(",")]
    if not depths or min(depths) < 1 or depths != sorted(set(depths)):
        raise SystemExit(f"--depths {a.depths}: expected increasing whole numbers ≥ 1")
    load0 = os.getloadavg()[0]
    rows = []
    for d in depths:
        mi, dr, variant, scene, target = mc.load_mitsuba(a.threads, max_depth=d, isa=a.mitsuba_isa)
        mc.mitsuba_y(mi, dr, scene, a.spp, 0)
        tm = min(mc.mitsuba_y(mi, dr, scene, a.spp, s)[1] for s in range(1, a.repeats + 1))
        tc = min(camsim_s(a.camsim, a.spp, d - 1, s, a.threads) for s in range(1, a.repeats + 1))
        rows.append((d, tm, tc))
    paths = mc.W * mc.H * a.spp
    mitsuba_kernel = mc.kernel_name(target)
    print(f"{mc.W}×{mc.H}, {a.spp} spp, {a.threads} threads, Mitsuba {mi.__version__} {variant} "
          f"(kernels for {mitsuba_kernel}), camsim kernel {mc.CAMSIM_ISA[-1]}; least of {a.repeats} renders each")
    print(f"{'Mitsuba max_depth':>17} {'camsim max_bounces':>18} {'Mitsuba s':>10} {'step':>7} "
          f"{'camsim s':>9} {'step':>7} {'camsim/Mitsuba':>15}")
    prev = (0.0, 0.0)
    for d, tm, tc in rows:
        print(f"{d:>17} {d - 1:>18} {tm:>10.3f} {tm - prev[0]:>+7.3f} {tc:>9.3f} {tc - prev[1]:>+7.3f} "
              f"{tc / tm:>15.3f}")
        prev = (tm, tc)
    d, tm, tc = rows[-1]
    print(f"at max_depth {d}: Mitsuba {paths / tm / 1e6:.3f} M paths/s, camsim {paths / tc / 1e6:.3f} M")
    print(f"CPU SIMD flags: {mc.machine_simd_flags()}")
    load = max(load0, os.getloadavg()[0])
    steps = ", ".join(f"d={d} {tc / tm:.3f}" for d, tm, tc in rows)
    print(f"DEPTHS camsim/Mitsuba time: {steps}  [< 1 = camsim faster]; CPU {mc.machine_cpu()}, "
          f"camsim kernel {mc.CAMSIM_ISA[-1]}, Mitsuba kernels for {mitsuba_kernel}, load {load:.1f}")


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"({time.perf_counter() - t0:.0f} s)")
