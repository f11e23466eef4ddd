"""Times Mitsuba 3 renders of one scene inside one process, for profiling it (docs/performance.md,
"What Mitsuba spends its time on"). Runs in the benchmark's venv (bench/peers.sh sets it up):

    DRJIT_LIBLLVM_PATH=/lib/x86_64-linux-gnu/libLLVM.so.19.1 perf record \\
      ~/.cache/rayfarm-bench/venv/bin/python bench/mitsuba_time.py SCENE.xml SCENE_DIR SPP W H THREADS

Loads SCENE.xml (with spp, resx, resy substituted) and renders it twice with THREADS threads; the
second render, after Dr.Jit has compiled and cached its kernel, is the one to quote."""
import sys
import time

t0 = time.time()
import drjit as dr
import mitsuba as mi

mi.set_variant('llvm_ad_rgb')
xml, scene_dir, spp, w, h, threads = sys.argv[1:7]
dr.set_thread_count(int(threads))
mi.file_resolver().prepend(scene_dir)
t1 = time.time()
scene = mi.load_file(xml, spp=int(spp), resx=int(w), resy=int(h))
t2 = time.time()
times = []
for seed in (1, 2):
    t = time.time()
    img = mi.render(scene, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    times.append(time.time() - t)
print('import %.2f s, load %.2f s, render %.2f s, again %.2f s, image mean %.6f'
      % (t1 - t0, t2 - t1, times[0], times[1], dr.mean(img.array)[0]))
