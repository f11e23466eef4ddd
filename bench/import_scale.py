#!/usr/bin/env python3
"""Import time against scene size: Mitsuba 3 scenes of N exact spheres (docs/performance.md,
"Scene import"), each rendered at 16x16 with 1 spp so the time is the import, the BVH build and
the process's start-up. A linear importer shows a constant time per sphere.

    bench/import_scale.py [--counts 5000,50000,500000] [--binary build/bin/rayfarm]
"""
import argparse
import os
import subprocess
import tempfile
import time

HEAD = ('<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">'
        '<lookat origin="0,0,500" target="0,0,0" up="0,1,0"/></transform><film type="hdrfilm">'
        '<integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>'
        '<emitter type="constant"/>\n')


def write_scene(path, n):
    with open(path, "w") as f:
        f.write(HEAD)
        for i in range(n):
            f.write(f'<shape type="sphere"><point name="center" x="{i % 100}" y="{i // 100 % 100}" '
                    f'z="{i // 10000}"/><float name="radius" value="0.1"/></shape>\n')
        f.write("</scene>\n")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser()
    ap.add_argument("--counts", default="5000,50000,500000")
    ap.add_argument("--binary", default=os.path.join(root, "build", "bin", "rayfarm"))
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        print(f"{'spheres':>8} {'best s':>8} {'us/sphere':>10}")
        for n in [int(c) for c in args.counts.split(",")]:
            scene = os.path.join(tmp, f"spheres{n}.xml")
            write_scene(scene, n)
            best = float("inf")
            for _ in range(args.rounds):
                t0 = time.perf_counter()
                subprocess.run([args.binary, "render", scene, "-o", os.path.join(tmp, "out.exr"),
                                "--spp", "1", "--passes", "1"],
                               check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                best = min(best, time.perf_counter() - t0)
            print(f"{n:>8} {best:>8.2f} {best / n * 1e6:>10.1f}")


if __name__ == "__main__":
    main()
