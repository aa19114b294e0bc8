"""Device time of one parallel loop carrying the weakly compressible pair pass's nine reductions (f32: three
sums, one largest, four smallest and a count, as wcsph/solver.py `_fluid_pass` returns them), with its count
read from a field against a fixed count, and without the reductions, at 10k, 200k and 1M entries.

    python tools/bench_reductions.py [--arch cuda] [--reps 200]

On CUDA a loop whose count is read from a field runs on Taichi's saturating grid whatever the count, and each
thread ends by adding its partials into the results: the cost follows the threads launched, not the work
(docs/performance.md, GPU, "Third round"). Each launch's time includes reading its result back."""

import argparse
import time

import taichi as ti


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default="cuda", choices=["cuda", "cpu"])
    ap.add_argument("--reps", type=int, default=200, help="launches timed per case")
    args = ap.parse_args(argv)
    ti.init(arch=getattr(ti, args.arch), default_fp=ti.f32, log_level=ti.WARN)
    sizes = (10_000, 200_000, 1_000_000)
    x = ti.field(ti.f32, sizes[-1])
    y = ti.field(ti.f32, sizes[-1])
    count = ti.field(ti.i32, ())

    def make(n: int, from_field: bool, reductions: bool):
        @ti.kernel
        def loop() -> ti.types.vector(9, ti.f64):
            s0, s1, s2, big = 0.0, 0.0, 0.0, 0.0
            m0, m1, m2, m3 = 1e30, 1e30, 1e30, 1e30
            bad = 0.0
            for m in range(count[None] if ti.static(from_field) else n):
                if m < count[None]:
                    v = x[m] * 1.0001 + 1e-6
                    y[m] = v
                    if ti.static(reductions):
                        s0 += v
                        s1 += v * v
                        s2 += 0.5 * v
                        ti.atomic_max(big, v)
                        ti.atomic_min(m0, v)
                        ti.atomic_min(m1, v + 1.0)
                        ti.atomic_min(m2, v + 2.0)
                        if v > 1e20:
                            bad += 1.0
                            ti.atomic_min(m3, float(m))
            return ti.Vector([s0, s1, s2, big, m0, m1, m2, m3, bad], ti.f64)
        return loop

    print("| entries | count | reductions | ms a launch |\n|---:|---|---|---:|")
    for n in sizes:
        count[None] = n
        for from_field in (True, False):
            for reductions in (True, False):
                loop = make(n, from_field, reductions)
                loop()  # compile
                ti.sync()
                t0 = time.perf_counter()
                for _ in range(args.reps):
                    loop()
                ti.sync()
                ms = (time.perf_counter() - t0) / args.reps * 1e3
                print(f"| {n:,} | {'read from a field' if from_field else 'fixed'} | "
                      f"{'nine' if reductions else 'none'} | {ms:.3f} |", flush=True)


if __name__ == "__main__":
    main()
