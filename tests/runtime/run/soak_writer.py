"""Soak measurement (not a test): ms per frame of runtime.run.output.Writer over N frames (default 6 000) on a
small mesh, the median of the first and of the last 200 frames. Constant cost per frame: the two agree.

    python tests/runtime/run/soak_writer.py [N]
"""
import sys, time, tempfile
import numpy as np
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.run.output import Writer

N = int(sys.argv[1]) if len(sys.argv) > 1 else 6000
mesh = generate_bar(cells=(4, 2, 2))
u = np.zeros((mesh.n_points, 3))
with tempfile.TemporaryDirectory() as tmp:
    w = Writer(tmp, mesh)
    times = []
    for k in range(N):
        t0 = time.perf_counter()
        w.write_frame(k, k * 1e-3, None, u, {"energy": np.zeros(mesh.n_cells)})
        times.append(time.perf_counter() - t0)
    w.close()
    t = np.array(times) * 1e3
    print(f"{N} frames, {mesh.n_points} nodes: first 200 frames {np.median(t[:200]):.3f} ms/frame (median), "
          f"last 200 {np.median(t[-200:]):.3f} ms/frame; mean first 500 {t[:500].mean():.3f}, last 500 {t[-500:].mean():.3f}")
