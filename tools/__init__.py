"""Timing, calibration and measurement scripts: each prints a table (and some write JSON evidence).
They sit outside the library packages and use only their public APIs; run them from the checkout's
root as `python -m tools.<name>` (they are not installed with the package).

    bench_train        seconds per training iteration of every method, by part (docs/recon.md)
    bench_threads      the same at 1 / 2 threads, and the rasterizer's thread scaling
    bench_raster       the rasterizer backends on synthetic and training-state models (docs/rasterizer.md)
    field_curves       learning curves, deformation MLP against per-Gaussian trajectories (docs/learning_curves.md)
    calibrate          the blur levels as speeds, from the speed study's rows (docs/benchmark.md)
    bench_ray          the benchmark's jobs serially against Ray tasks (docs/benchmark.md)
    bench_simulator    the event simulator's kernels (docs/simulator.md)
    bench_formats      event file formats: size, write / read speed, round trips (docs/formats.md)
    bench_engines      Blender render engines and their settings against the events (docs/dataset.md)
    bench_render_rate  what the render rate costs and buys (docs/dataset.md)
    bench_adaptive     adaptive temporal sampling against rendering every frame (docs/dataset.md)
    dataset_summary    a generated dataset's times, events, sizes and blur levels (docs/dataset.md)
    bench_viewer       the browser viewer's frame and event throughput (docs/viewer.md)
"""
