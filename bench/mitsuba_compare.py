"""camsim vs Mitsuba 3 on Mitsuba's cornell_box(): paths/s, equal-spp and
equal-time RMSE of CIE Y luminance against one converged Mitsuba reference.

Run through bench/mitsuba_compare.sh (it installs Mitsuba and builds camsim).
Every RMSE, for both renderers, is computed here by the same code:

    RMSE = sqrt(mean_px (Y - Y_ref)^2 - mean_px Var[Y_ref]) / mean_px Y_ref

Y_ref is a high-spp Mitsuba render made of independent batches; Var[Y_ref]
is the variance of its mean estimated from the batch spread, so the RMSE is
against the converged image, not against a noisy one.

Equal time: camsim gets the spp that fits in Mitsuba's measured wall time
(from camsim's own equal-spp paths/s); its RMSE is then scaled by
sqrt(t_camsim / t_mitsuba) (RMSE of an unbiased estimator ~ 1/sqrt(time)) to
remove the small leftover time mismatch. The same is reported with CPU
time, which is less sensitive to the load of a shared machine. Each timed
measurement is repeated with seeds 1..4 (times and MSEs averaged; ± is the
standard error from their spread): one image's RMSE scatters by ±5 %, because most of it comes from a
few hundred pixels on the emitter's edge. RMSE is reported over all pixels
and over all but the emitter ±2 px ("light transport").

Mitsuba is timed to kernel completion (dr.sync_thread()): its LLVM kernels
run asynchronously, and timing mi.render() + dr.eval() alone measures the
launch (tens of M "paths/s"), not the render.
"""

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import time

import numpy as np

# Y from Mitsuba's linear sRGB: the middle row of its sRGB -> XYZ matrix.
SRGB_TO_Y = np.array([0.212671, 0.715160, 0.072169])
W = H = 256


def write_pfm(path, img):
    img = np.asarray(img, dtype="<f4")
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(b"Pf\n%d %d\n-1.0\n" % (img.shape[1], img.shape[0]))
        f.write(np.ascontiguousarray(img[::-1]).tobytes())
    os.replace(tmp, path)


def read_pfm(path):
    with open(path, "rb") as f:
        data = f.read()
    tok = data.split(maxsplit=4)
    if tok[0] != b"Pf":
        sys.exit(f"{path}: not a grey PFM")
    w, h = int(tok[1]), int(tok[2])
    img = np.frombuffer(data[len(data) - 4 * w * h :], dtype="<f4").reshape(h, w)
    return img[::-1].astype(np.float64)


def load_mitsuba(threads, max_depth=7):
    import drjit as dr
    import mitsuba as mi

    variant = None
    for v in ("llvm_ad_spectral", "scalar_spectral"):
        try:
            mi.set_variant(v)
            variant = v
            break
        except Exception as e:  # noqa: BLE001 - report and try the next one
            print(f"note: Mitsuba variant {v} unavailable: {e}", file=sys.stderr)
    if variant is None:
        sys.exit("no spectral Mitsuba variant available")
    if variant != "llvm_ad_spectral":
        print("WARNING: llvm_ad_spectral unavailable (install libllvm19); timing scalar_spectral", file=sys.stderr)
    dr.set_thread_count(threads)
    d = mi.cornell_box()
    d["integrator"] = {"type": "path", "max_depth": max_depth}
    d["sensor"]["film"]["width"] = W
    d["sensor"]["film"]["height"] = H
    # Box filter: each sample lands in its own pixel, as in camsim (the default
    # Gaussian spreads samples over neighbours: lower per-pixel noise, blur).
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    scene = mi.load_dict(d)
    return mi, dr, variant, scene


def mitsuba_y(mi, dr, scene, spp, seed):
    """Render; return (Y image, wall s, CPU s of this process)."""
    t0, c0 = time.perf_counter(), time.process_time()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    a = np.array(img, dtype=np.float64)
    t, c = time.perf_counter() - t0, time.process_time() - c0
    return a[..., :3] @ SRGB_TO_Y, t, c


def mitsuba_reference(mi, dr, scene, spp, batches, pass_spp, cache):
    """Mean Y and variance of the mean over `batches` independent batches."""
    y_path, v_path = cache + "_y.pfm", cache + "_var.pfm"
    if os.path.exists(y_path) and os.path.exists(v_path):
        print(f"Mitsuba reference: cached {y_path}")
        return read_pfm(y_path), read_pfm(v_path)
    per_batch = spp // batches
    passes = max(1, per_batch // pass_spp)
    print(f"Mitsuba reference: {batches} batches × {passes} passes × {per_batch // passes} spp (once; cached) …", flush=True)
    t0 = time.perf_counter()
    means = []
    seed = 1000
    for _ in range(batches):
        acc = np.zeros((H, W))
        for _ in range(passes):
            y, _, _ = mitsuba_y(mi, dr, scene, per_batch // passes, seed)
            seed += 1
            acc += y
        means.append(acc / passes)
    m = np.stack(means)
    ref = m.mean(axis=0)
    var = m.var(axis=0, ddof=1) / batches
    write_pfm(y_path, ref)
    write_pfm(v_path, var)
    print(f"  {batches * passes * (per_batch // passes)} spp in {time.perf_counter() - t0:.0f} s → {y_path}")
    return ref, var


# The machine as camsim's `bench render` reports it ("cpu: MODEL (VECTOR WIDTH)").
CAMSIM_CPU = []
# The render kernel level camsim ran (`render_isa=` of its bench line; CAMSIM_RENDER_ISA lowers it).
CAMSIM_ISA = []
# Whether camsim traced 16 paths at a time (`packets=` of its bench line; default at avx2 and avx512, CAMSIM_RENDER_PACKETS=0|1 forces it).
CAMSIM_PACKETS = []
# Packets each row kept in flight, their rays regrouped before each cast (`in_flight=`; CAMSIM_PACKETS_IN_FLIGHT sets it).
CAMSIM_IN_FLIGHT = []


def machine_cpu():
    """CPU model and vector width: camsim's own report, else /proc/cpuinfo."""
    if CAMSIM_CPU:
        return CAMSIM_CPU[-1]
    info = cpuinfo()
    if info is None:
        return "unknown"
    model, flags = info
    width = "avx512f" if "avx512f" in flags else "avx2+fma" if {"avx2", "fma"} <= flags else "sse"
    return f"{model} ({width})"


def cpuinfo():
    """(model name, set of flags) of the first CPU in /proc/cpuinfo; None off Linux."""
    try:
        info = open("/proc/cpuinfo").read().splitlines()
        model = next(line.split(":", 1)[1].strip() for line in info if line.startswith("model name"))
        flags = next(line.split(":", 1)[1].split() for line in info if line.startswith("flags"))
    except (OSError, StopIteration):
        return None
    return " ".join(model.split()), set(flags)


# The vector-instruction flags the comparison depends on, as /proc/cpuinfo
# lists them (Mitsuba's LLVM back end and camsim's kernels pick their width
# from these).
SIMD_FLAGS = ("sse4_1", "sse4_2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512cd",
              "avx512bw", "avx512vl", "avx512_vnni", "avx512_bf16", "avx512vbmi", "avx512ifma")


def machine_simd_flags():
    """The CPU's SIMD flags of SIMD_FLAGS, in that order ('unknown' off Linux)."""
    info = cpuinfo()
    if info is None:
        return "unknown"
    flags = info[1]
    return " ".join(f for f in SIMD_FLAGS if f in flags) or "none of " + " ".join(SIMD_FLAGS)


# camsim's batches and sampler for the timed renders (set in main()).
CAMSIM_BATCHES = [1]
CAMSIM_SAMPLER = ["sobol"]


def camsim_bench(camsim, args):
    """`camsim bench render` with `args` (no reference render, the renderer's
    BVH): its machine line's key=value pairs; the CPU, kernel and packet mode
    are noted for the RATIO line."""
    cmd = [camsim, "bench", "render", "--ref-spp", "0", "--bvh", "bvh4", *args]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    CAMSIM_CPU.extend(line[len("cpu: "):] for line in out.splitlines() if line.startswith("cpu: "))
    kv_line = [line for line in out.splitlines() if line.startswith("camsim-bench ")][-1]
    kv = dict(re.findall(r"(\w+)=(\S+)", kv_line))
    CAMSIM_ISA.append(kv.get("render_isa", "?"))
    CAMSIM_PACKETS.append(kv.get("packets", "false") == "true")
    CAMSIM_IN_FLIGHT.append(kv.get("in_flight", "1"))
    return kv


def run_camsim(camsim, spp, seed, y_out, threads):
    kv = camsim_bench(camsim, ["--spp", str(spp), "--threads", str(threads), "--seed", str(seed),
                               "--y-out", y_out, "--batches", str(CAMSIM_BATCHES[0]),
                               "--sampler", CAMSIM_SAMPLER[0]])
    return read_pfm(y_out), float(kv["wall_s"]), float(kv["cpu_s"])


def rel_rmse(y, ref, var):
    mse = np.mean((y - ref) ** 2) - np.mean(var)
    return np.sqrt(max(mse, 0.0)) / ref.mean()


def file_sha(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:12]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--camsim", required=True)
    ap.add_argument("--cache", required=True, help="directory for cached references")
    ap.add_argument("--spp", type=int, default=32, help="Mitsuba's timed spp (also the equal-spp comparison)")
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--ref-batches", type=int, default=8)
    ap.add_argument("--camsim-conv-spp", type=int, default=256, help="per half of camsim's converged image (0: skip)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seeds", type=int, default=4, help="independent timed renders per measurement")
    ap.add_argument("--batches", type=int, default=1,
                    help="camsim's sample batches (1: one image, like Mitsuba's; 8: the renderer's default, with a standard error)")
    ap.add_argument("--sampler", default="sobol", help="camsim's sampler: sobol or independent")
    a = ap.parse_args()
    CAMSIM_BATCHES[0] = a.batches
    CAMSIM_SAMPLER[0] = a.sampler
    os.makedirs(a.cache, exist_ok=True)

    mi, dr, variant, scene = load_mitsuba(a.threads)
    print(f"Mitsuba {mi.__version__} {variant}, {a.threads} threads; scene cornell_box(), {W}×{H}, max_depth 7, box filter")
    print("  Jakob–Hanika coefficients (must equal camsim's src/render/bench.rs JH_*):")
    bench_rs = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src", "render", "bench.rs")).read()
    for name, rgb in (("WHITE", [0.885809, 0.698859, 0.666422]), ("GREEN", [0.105421, 0.37798, 0.076425]),
                      ("RED", [0.570068, 0.0430135, 0.0443706]), ("LIGHT", [18.387 / 36.774, 13.9873 / 36.774, 6.75357 / 36.774])):
        c = [float(x) for x in mi.srgb_model_fetch(rgb)]
        m = re.search(r"JH_" + name + r": \[f64; 3\] = \[([^\]]*)\]", bench_rs)
        ours = [float(x) for x in m.group(1).replace(",", " ").split()] if m else None
        same = ours is not None and np.allclose(c, ours, rtol=1e-6, atol=0)
        print(f"    {name.lower()}: {c} {'= camsim' if same else 'DIFFERS from camsim ' + str(ours)}")
        if not same:
            print("WARNING: camsim's bench scene does not use this Mitsuba's spectra; update JH_* in src/render/bench.rs", file=sys.stderr)
    print(f"  load average: {os.getloadavg()[0]:.1f} (2-core machine; wall-clock rates depend on it)", flush=True)

    key = f"mitsuba-{mi.__version__}-{variant}-{a.ref_spp}spp-{a.ref_batches}b"
    ref, var = mitsuba_reference(mi, dr, scene, a.ref_spp, a.ref_batches, 128, os.path.join(a.cache, key))
    print(f"  reference mean Y {ref.mean():.5f}; its own noise {np.sqrt(var.mean()) / ref.mean() * 100:.3f} % RMS (subtracted)")

    # camsim's converged image: two independent halves give its own noise.
    if a.camsim_conv_spp > 0:
        tag = f"camsim-{file_sha(a.camsim)}-{a.camsim_conv_spp}spp-{a.sampler}-{a.batches}b"
        halves = []
        for seed in (101, 102):
            p = os.path.join(a.cache, f"{tag}-seed{seed}_y.pfm")
            if not os.path.exists(p):
                print(f"camsim converged image: {a.camsim_conv_spp} spp, seed {seed} (cached per binary) …", flush=True)
                run_camsim(a.camsim, a.camsim_conv_spp, seed, p, a.threads)
            halves.append(read_pfm(p))
        c = 0.5 * (halves[0] + halves[1])
        c_var = np.mean((halves[0] - halves[1]) ** 2) / 4.0
        d = c - ref
        bias_rmse = np.sqrt(max(np.mean(d**2) - c_var - var.mean(), 0.0)) / ref.mean()
        b = 16
        cb = c.reshape(H // b, b, W // b, b).mean(axis=(1, 3))
        rb = ref.reshape(H // b, b, W // b, b).mean(axis=(1, 3))
        rel = cb / rb - 1.0
        print(f"converged images (camsim {2 * a.camsim_conv_spp} spp vs Mitsuba {a.ref_spp} spp), CIE Y:")
        print(f"  mean Y ratio camsim/Mitsuba = {c.mean() / ref.mean():.4f}")
        print(f"  16×16-pixel blocks: RMS relative difference {np.sqrt(np.mean(rel**2)) * 100:.2f} %, max {np.abs(rel).max() * 100:.2f} %")
        raw = np.sqrt(np.mean(d**2)) / ref.mean()
        noise = np.sqrt(c_var + var.mean()) / ref.mean()
        print(f"  per-pixel RMS difference {raw * 100:.2f} % of the mean, of which noise {noise * 100:.2f} % "
              f"→ systematic part {bias_rmse * 100:.2f} %")

    # Pixels within 2 px of the emitter: their error is pixel-coverage noise
    # at the light's edge (Y ≈ 13 next to ≈ 0.1), the same for both renderers,
    # heavy-tailed, and ~85 % of the whole-image MSE at 32 spp. The second
    # metric leaves them out and measures light transport only.
    light = ref > 1.0
    near = np.zeros_like(light)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            near |= np.roll(np.roll(light, dy, 0), dx, 1)
    masks = {"all pixels": np.ones_like(light), "light transport (emitter ±2 px excluded)": ~near}

    def rmses(imgs):
        """Relative RMSE per mask (MSE averaged over the seeds' images) and its
        relative standard error from the seed-to-seed spread."""
        out = {}
        for k, m in masks.items():
            mse = np.array([np.mean(((y - ref) ** 2 - var)[m]) for y in imgs])
            mean = max(mse.mean(), 1e-30)
            se = mse.std(ddof=1) / np.sqrt(len(mse)) if len(mse) > 1 else 0.0
            out[k] = (np.sqrt(mean) / ref[m].mean(), 0.5 * se / mean)
        return out

    seeds = tuple(range(1, a.seeds + 1))
    paths = W * H * a.spp
    # Mitsuba timed (kernel compiled by a warm-up render of the same spp).
    mitsuba_y(mi, dr, scene, a.spp, 0)
    runs = [mitsuba_y(mi, dr, scene, a.spp, s) for s in seeds]
    for s, r in zip(seeds, runs):
        write_pfm(os.path.join(a.cache, f"mitsuba_{a.spp}spp_seed{s}_y.pfm"), r[0])
    tm, cm = np.mean([r[1] for r in runs]), np.mean([r[2] for r in runs])
    rm = rmses([r[0] for r in runs])
    print(f"Mitsuba: {a.spp} spp in {tm:.3f} s wall ({cm:.3f} CPU s), mean of seeds {seeds}: {paths / tm / 1e6:.3f} M paths/s, "
          f"{paths / cm / 1e6:.3f} M paths per CPU-s (4 wavelengths per path)")

    def camsim_runs(spp, tag):
        rs = [run_camsim(a.camsim, spp, s, os.path.join(a.cache, f"camsim_{tag}_seed{s}_y.pfm"), a.threads) for s in seeds]
        return [r[0] for r in rs], np.mean([r[1] for r in rs]), np.mean([r[2] for r in rs])

    yc, tc, cc = camsim_runs(a.spp, "equal_spp")
    rc = rmses(yc)
    pps_c = paths / tc
    print(f"camsim:  {a.spp} spp in {tc:.3f} s wall ({cc:.3f} CPU s), mean of seeds {seeds}: {pps_c / 1e6:.3f} M paths/s, "
          f"{paths / cc / 1e6:.3f} M paths per CPU-s (31 bands per path)")

    spp_eq = max(1, round(tm * pps_c / (W * H)))
    if spp_eq == a.spp:
        ye, te, ce = yc, tc, cc
    else:
        ye, te, ce = camsim_runs(spp_eq, "equal_time")
    re_ = rmses(ye)
    print(f"camsim at equal time: {spp_eq} spp in {te:.3f} s wall (Mitsuba {tm:.3f} s); RMSE scaled by sqrt(t_camsim/t_Mitsuba) = {np.sqrt(te / tm):.3f} to exactly equal time")
    print()
    print("relative RMSE of CIE Y against the converged Mitsuba reference:")
    res = {}
    for k in masks:
        eq_wall = re_[k][0] * np.sqrt(te / tm)
        eq_cpu = rc[k][0] * np.sqrt(cc / cm)
        res[k] = (rc[k][0] / rm[k][0], eq_wall / rm[k][0], eq_cpu / rm[k][0])
        # Relative standard errors of the ratios (seed-to-seed spread).
        se_spp = np.hypot(rc[k][1], rm[k][1])
        se_time = np.hypot(re_[k][1], rm[k][1])
        print(f"  {k}:")
        print(f"    equal spp ({a.spp}): Mitsuba {rm[k][0] * 100:.2f} %, camsim {rc[k][0] * 100:.2f} %  → camsim/Mitsuba {res[k][0]:.3f} ± {res[k][0] * se_spp:.3f}")
        print(f"    equal time ({tm:.2f} s wall): Mitsuba {rm[k][0] * 100:.2f} %, camsim {eq_wall * 100:.2f} % ({spp_eq} spp, measured {re_[k][0] * 100:.2f} % in {te:.2f} s) "
              f"→ camsim/Mitsuba {res[k][1]:.3f} ± {res[k][1] * se_time:.3f}; at equal CPU time {res[k][2]:.3f}")
    k_all, k_lt = list(masks)
    print()
    simd_flags = machine_simd_flags()
    print(f"CPU SIMD flags: {simd_flags}")
    print(f"RATIO camsim/Mitsuba: paths/s {pps_c / (paths / tm):.3f} (wall), {cm / cc:.3f} (CPU); "
          f"equal-time RMSE {res[k_all][1]:.3f} (wall), {res[k_all][2]:.3f} (CPU); "
          f"light transport only {res[k_lt][1]:.3f} (wall); equal-spp RMSE {res[k_all][0]:.3f}  [RMSE < 1 = camsim better]; "
          f"CPU {machine_cpu()}, camsim kernel {CAMSIM_ISA[-1] if CAMSIM_ISA else '?'} "
          f"({f'16 paths at a time, {CAMSIM_IN_FLIGHT[-1]} packets in flight' if CAMSIM_PACKETS and CAMSIM_PACKETS[-1] else 'one path at a time'}), "
          f"camsim sampler {a.sampler} in {a.batches} batch(es), load {os.getloadavg()[0]:.1f}")
    with open(os.path.join(a.cache, "last_result.json"), "w") as f:
        json.dump({"load_average": os.getloadavg()[0], "cpu": machine_cpu(), "simd_flags": simd_flags,
                   "mitsuba": {"variant": variant, "spp": a.spp, "wall_s": tm, "cpu_s": cm, "rel_rmse": rm},
                   "camsim": {"spp": a.spp, "wall_s": tc, "cpu_s": cc, "rel_rmse": rc},
                   "camsim_equal_time": {"spp": spp_eq, "wall_s": te, "cpu_s": ce, "rel_rmse": re_}},
                  f, indent=1, default=float)


if __name__ == "__main__":
    main()
