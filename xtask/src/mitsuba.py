"""Renders a scene exported by `cargo xtask mitsuba` with Mitsuba 3 and compares it with
lucent's Monte Carlo image of the same scene. Reads the JSON config given as argv[1],
prints one JSON object with the comparison and the throughput of each variant."""

import json
import sys
import time

import mitsuba as mi

cfg = json.load(open(sys.argv[1]))
results = {"variants": {}}

for variant in cfg["variants"]:
    try:
        mi.set_variant(variant)
    except Exception as e:  # a variant that cannot load (missing LLVM) is reported, not fatal
        results["variants"][variant] = {"error": str(e)}
        continue
    T = mi.ScalarTransform4f
    lo, hi = cfg["bounds"]
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    half = [(b - a) / 2 for a, b in zip(lo, hi)]
    extent = [b - a for a, b in zip(lo, hi)]
    cam = cfg["camera"]
    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": cfg["max_depth"], "rr_depth": 5},
        "sensor": {
            "type": "perspective",
            "fov": cam["fov"],
            "fov_axis": "y",
            "to_world": T().look_at(origin=cam["position"], target=cam["look_at"], up=cam["up"]),
            "film": {"type": "hdrfilm", "width": cfg["width"], "height": cfg["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": cfg["spp"]},
        },
        "cube": {
            "type": "cube",
            "to_world": T().translate(centre).scale(half),
            "bsdf": {"type": "null"},
            "interior": {
                "type": "heterogeneous",
                "sigma_t": {"type": "gridvolume", "filename": cfg["volume"], "filter_type": "trilinear",
                            "to_world": T().translate(lo).scale(extent)},
                "albedo": {"type": "rgb", "value": cfg["albedo"]},
                "phase": {"type": "hg", "g": cfg["g"]},
                "scale": 1.0,
            },
        },
    }
    for i, light in enumerate(cfg["lights"]):
        if light["kind"] == "directional":
            scene[f"light{i}"] = {"type": "directional", "direction": light["direction"],
                                  "irradiance": {"type": "rgb", "value": light["value"]}}
        elif light["kind"] == "sky":
            scene[f"light{i}"] = {"type": "constant", "radiance": {"type": "rgb", "value": light["value"]}}
    loaded = mi.load_dict(scene)
    mi.render(loaded, spp=4)  # warm-up (JIT compilation for the llvm variants)
    start = time.time()
    image = mi.render(loaded, spp=cfg["spp"])
    import numpy as np
    theirs = np.array(image, dtype=np.float32)[:, :, :3]
    seconds = time.time() - start
    out = cfg["output_prefix"] + variant + ".npy"
    # numpy, not EXR: Mitsuba's threaded EXR writer hung in this sandbox.
    np.save(out, theirs)
    shape = (cfg["height"], cfg["width"], 3)
    mine = np.fromfile(cfg["lucent_image"], dtype="<f4").reshape(shape)
    err = np.fromfile(cfg["lucent_stderr"], dtype="<f4").reshape(shape)
    paths = cfg["width"] * cfg["height"] * cfg["spp"]
    mean_mine, mean_theirs = float(mine.mean()), float(theirs.mean())
    # Per-pixel z-scores with lucent's standard error and Mitsuba's, estimated from the same
    # noise level (equal spp, same estimator family): sigma = sqrt(2) * lucent's error.
    # Only pixels whose paths meet the medium have noise; background pixels are exact in both.
    noisy = err > 1e-5
    z = ((mine - theirs) / (err * np.sqrt(2.0)))[noisy]
    # Per pixel, 64 paths see heavy-tailed noise (rare bright sun paths), so also compare
    # block means, where the central limit theorem holds.
    blocks = {}
    for b in (8, 16):
        n = cfg["width"] // b
        mb = mine[: n * b, : n * b].reshape(n, b, n, b, 3).mean((1, 3))
        tb = theirs[: n * b, : n * b].reshape(n, b, n, b, 3).mean((1, 3))
        eb = np.sqrt((err[: n * b, : n * b].reshape(n, b, n, b, 3) ** 2).sum((1, 3))) / (b * b)
        keep = eb > 1e-5
        zb = ((mb - tb) / (eb * np.sqrt(2.0)))[keep]
        blocks[f"{b}x{b}"] = {"mean_z": float(zb.mean()), "rms_z": float(np.sqrt((zb ** 2).mean())),
                              "fraction_beyond_4": float((np.abs(zb) > 4).mean())}
    # Per pixel, 64 paths see heavy-tailed noise (rare bright sun paths), so also compare
    # block means, where the central limit theorem holds.
    blocks = {}
    for b in (8, 16):
        n = cfg["width"] // b
        mb = mine[: n * b, : n * b].reshape(n, b, n, b, 3).mean((1, 3))
        tb = theirs[: n * b, : n * b].reshape(n, b, n, b, 3).mean((1, 3))
        eb = np.sqrt((err[: n * b, : n * b].reshape(n, b, n, b, 3) ** 2).sum((1, 3))) / (b * b)
        keep = eb > 1e-5
        zb = ((mb - tb) / (eb * np.sqrt(2.0)))[keep]
        blocks[f"{b}x{b}"] = {"mean_z": float(zb.mean()), "rms_z": float(np.sqrt((zb ** 2).mean())),
                              "fraction_beyond_4": float((np.abs(zb) > 4).mean())}
    results["variants"][variant] = {
        "seconds": seconds,
        "paths_per_second": paths / seconds,
        "mean": mean_theirs,
        "mean_lucent": mean_mine,
        "relative_mean_difference": (mean_mine - mean_theirs) / mean_theirs,
        "mean_z": float(z.mean()),
        "rms_z": float(np.sqrt((z ** 2).mean())),
        "noisy_pixels": int(noisy.sum()),
        "blocks": blocks,
        "max_background_difference": float(np.abs(mine - theirs)[~noisy].max()) if (~noisy).any() else 0.0,
        "image": out,
    }
print(json.dumps(results))
