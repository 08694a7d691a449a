"""Timing, calibration and measurement scripts: each prints a table (and some write JSON evidence).
They sit outside the library packages and use only their public APIs; run them from the checkout's
root as `python -m tools.<name>` (they are not installed with the package).

    bench_train        seconds per training iteration of every method, by part (docs/design/recon.md)
    bench_threads      the same at 1 / 2 threads, and the rasterizer's thread scaling
    bench_raster       the rasterizer backends on synthetic and training-state models (docs/design/rasterizer.md)
    field_curves       learning curves, deformation MLP against per-Gaussian trajectories (docs/results/learning_curves.md)
    calibrate          the blur levels as speeds, from the speed study's rows (docs/results/benchmark.md)
    bench_ray          the benchmark's jobs serially against Ray tasks (docs/results/benchmark.md)
    bench_simulator    the event simulator's kernels (docs/design/simulator.md)
    bench_formats      event file formats: size, write / read speed, round trips (docs/reference/formats.md)
    bench_engines      Blender render engines and their settings against the events (docs/design/dataset.md)
    bench_render_rate  what the render rate costs and buys (docs/design/dataset.md)
    bench_adaptive     adaptive temporal sampling against rendering every frame (docs/design/dataset.md)
    dataset_summary    a generated dataset's times, events, sizes and blur levels (docs/design/dataset.md)
    bench_viewer       the browser viewer's frame and event throughput (docs/guides/viewer.md)
    ground_truth_summary  a dataset's ground truth: cost, warp check, events per object, one view drawn
                       (docs/results/dataset.md)
    docs_reference     the generated CLI and config reference pages (docs/reference/)
"""
