"""RaNA speed: the C++ kernels against the torch reference, in the same run.

Default problem (issue 3): a 512x512 layout with 0..6 bins per pixel (mean ~3), radius 3.5, 4 heads x 16
channels. Prints forward and forward+backward time, query-key pairs per second, GFLOP/s (4*d FLOPs per
pair per head, the usual attention count: q.k and p.v, multiply and add), peak memory of the process, and
the speed-up over the reference on a size the reference can handle (``--ref-size``).
Freed memory is kept for reuse (heap.py) and torch's allocator asks for no transparent huge pages, as in the ranad
CLI (THP_MEM_ALLOC_ENABLE=1 to compare: see ranad_cli/main.py for why the CLI leaves them off).
Both memory layouts of q, k, v are measured at --size (see problem()).
With a GPU, the CUDA kernels run the same problem too; `--device cuda` runs only them: the staged design (the
default, at each --chunks size) against the one-thread design it replaced, in the same process.
Usage: python bench/rana.py [--size 512 --radius 3.5 --heads 4 --dim 16 --threads N --layout both --repeats 5]
                            [--device cuda --chunks 16,32,64,128]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time

import torch

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from ranad_core import heap  # noqa: E402
from ranad_core.rana import rana, self_attention_layout  # noqa: E402
from ranad_core.rana.neighborhood import disc  # noqa: E402


def problem(size: int, heads: int, dim: int, seed: int = 0, layout: str = "natural"):
    """offsets and q, k, v [N, heads, dim]; layout "channel-major" gives them as transposed views of contiguous
    [N, dim, heads] tensors, the layout a projection can write so that the kernels need no copy."""
    g = torch.Generator().manual_seed(seed)
    counts = torch.randint(0, 7, (size * size,), generator=g)
    offsets = torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(counts, 0)])
    n = int(offsets[-1])
    if layout == "channel-major":
        q, k, v = (torch.randn(n, dim, heads, generator=g).transpose(1, 2) for _ in range(3))
    else:
        q, k, v = (torch.randn(n, heads, dim, generator=g) for _ in range(3))
    return offsets, q, k, v


def pairs_of(offsets, size, radius) -> int:
    """Query-key pairs of the self-attention layout, counted per disc row without materialising them."""
    d = disc(radius)
    counts = (offsets[1:] - offsets[:-1]).reshape(size, size)
    ys, xs = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    keys = torch.zeros(size, size, dtype=torch.int64)
    for dy, dx0, dx1 in zip(d.dy, d.dx0, d.dx1):
        py = ys + dy
        a, b = (xs + dx0).clamp(0, size - 1), (xs + dx1).clamp(0, size - 1)
        ok = (py >= 0) & (py < size) & (xs + dx1 >= 0) & (xs + dx0 < size)
        pyc = py.clamp(0, size - 1)
        keys += torch.where(ok, offsets[pyc * size + b + 1] - offsets[pyc * size + a], 0)
    return int((counts * keys).sum())


def cpu_summary() -> str:
    """The CPU model and the SIMD width the kernels were built for (-march=native: 16 float lanes with AVX-512,
    8 with AVX2), since figures from different machines are not comparable."""
    model, flags = "unknown CPU", ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and model == "unknown CPU":
                    model = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and not flags:
                    flags = line
    except OSError:
        pass
    simd = "AVX-512, 16 lanes" if " avx512f" in flags else "AVX2, 8 lanes" if " avx2" in flags else "no AVX2"
    return f"{model} ({simd})"


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def run(size, radius, heads, dim, backend, repeats, layout="natural"):
    offsets, q, k, v = problem(size, heads, dim, layout=layout)
    qp, ko, ks = self_attention_layout(offsets, size, size)
    bias = torch.zeros(heads, 2 * int(radius) + 1, 2 * int(radius) + 1)
    if backend == "cuda":  # everything on the GPU, timings synchronised
        q, k, v, qp, ko, bias = (t.cuda() for t in (q, k, v, qp, ko, bias))
    sync = torch.cuda.synchronize if backend == "cuda" else (lambda: None)

    def timed_fwd():
        rana(q, k, v, qp, ko, ks, radius, bias, backend=backend)
        sync()

    fwd = best_of(timed_fwd, repeats)
    qg, kg, vg, bg = (t.detach().requires_grad_(True) for t in (q, k, v, bias))

    # the upstream gradient, made once: in a training step it is the next layer's output, not this op's work (made
    # inside the timed call, its fresh 200 MB allocation cost ~200 ms of page faults)
    gout = torch.ones(q.shape[0], heads, v.shape[2], device=q.device)

    def fwd_bwd():  # the gradients returned, not accumulated into .grad (as a training step with zeroed grads)
        out = rana(qg, kg, vg, qp, ko, ks, radius, bg, backend=backend)
        torch.autograd.grad(out, (qg, kg, vg, bg), gout)
        sync()

    both = best_of(fwd_bwd, repeats)
    return fwd, both, pairs_of(offsets, size, radius), int(offsets[-1])


def main() -> None:
    heap.keep_freed_memory()   # as the ranad CLI does
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--ref-size", type=int, default=96)
    ap.add_argument("--radius", type=float, default=3.5)
    ap.add_argument("--heads", type=int, default=4)
    ap.add_argument("--dim", type=int, default=16)
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--layout", choices=("natural", "channel-major", "both"), default="both",
                    help="memory layout of q, k, v at --size (both are [N, heads, d] tensors; see problem()); "
                         "channel-major is what the model's projections write, natural needs two copies per call")
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                    help="cuda: only the CUDA kernels, staged (at each --chunks) against one-thread")
    ap.add_argument("--chunks", default="16,32,64,128", help="rows per shared-memory chunk of the staged CUDA kernels")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    if args.device == "cuda":
        cuda_designs(args)
        return
    flop = 4 * args.dim * args.heads
    layouts = ("channel-major", "natural") if args.layout == "both" else (args.layout,)
    print(f"RaNA bench: radius {args.radius}, {args.heads} heads x {args.dim}, {args.threads} threads, "
          f"best of {args.repeats}, torch {torch.__version__}")
    print(f"CPU: {cpu_summary()}")
    rows = []
    runs = [("C++ kernels", args.size, "cpu", layout) for layout in layouts]
    runs += [("C++ kernels", args.ref_size, "cpu", "natural"), ("reference", args.ref_size, "reference", "natural")]
    for label, size, backend, layout in runs:
        fwd, both, pairs, bins = run(size, args.radius, args.heads, args.dim, backend, args.repeats, layout)
        rows.append((label, size, fwd, both, pairs))
        if backend == "cpu" and size == args.size:
            peak_cpp = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{label:12s} {size}x{size} {layout:13s} ({bins} bins, {pairs / 1e6:.1f} M pairs): "
              f"forward {fwd * 1e3:8.1f} ms = {pairs / fwd / 1e6:6.1f} M pairs/s, {pairs * flop / fwd / 1e9:5.1f} "
              f"GFLOP/s | forward+backward {both * 1e3:8.1f} ms = {pairs / both / 1e6:6.1f} M pairs/s")
    if torch.cuda.is_available():  # the CUDA kernels on the GPU present, same problem
        fwd, both, pairs, bins = run(args.size, args.radius, args.heads, args.dim, "cuda", args.repeats, layouts[0])
        print(f"CUDA kernels {args.size}x{args.size} on {torch.cuda.get_device_name()}: forward {fwd * 1e3:8.2f} ms = "
              f"{pairs / fwd / 1e6:7.1f} M pairs/s | forward+backward {both * 1e3:8.2f} ms = "
              f"{pairs / both / 1e6:7.1f} M pairs/s ({rows[0][2] / fwd:.1f}x / {rows[0][3] / both:.1f}x the CPU run)")
    else:
        print("CUDA kernels: not measured (no GPU here)")
    _, _, f_small, b_small, _ = rows[-2]
    _, _, f_ref, b_ref, _ = rows[-1]
    print(f"speed-up over the reference at {args.ref_size}x{args.ref_size}: forward {f_ref / f_small:.0f}x, "
          f"forward+backward {b_ref / b_small:.0f}x")
    print(f"peak resident memory: {peak_cpp:.0f} MB after the C++ runs at {args.size}x{args.size}, "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB after the reference at "
          f"{args.ref_size}x{args.ref_size} (its pair list is materialised)")


def cuda_designs(args) -> None:
    """The staged CUDA kernels at each chunk size against the one-thread kernels, same problem, same process."""
    from ranad_core.rana.extension import load_cuda_extension

    if not torch.cuda.is_available():
        raise SystemExit("bench/rana.py --device cuda: no CUDA GPU here")
    ext = load_cuda_extension()
    before = ext.configure(True, 0)  # the options in force, restored at the end
    layout = "channel-major" if args.layout == "both" else args.layout
    print(f"RaNA CUDA bench on {torch.cuda.get_device_name()}: {args.size}x{args.size} {layout}, radius "
          f"{args.radius}, {args.heads} heads x {args.dim}, best of {args.repeats}, torch {torch.__version__}")
    designs = [("one-thread", False, 0)] + [(f"staged, {c} rows/chunk", True, int(c)) for c in args.chunks.split(",")]
    base = None
    for label, staged, chunk in designs:
        ext.configure(staged, chunk)
        run(args.size, args.radius, args.heads, args.dim, "cuda", 1, layout)  # warm-up (and the build)
        fwd, both, pairs, bins = run(args.size, args.radius, args.heads, args.dim, "cuda", args.repeats, layout)
        base = base or (fwd, both)
        print(f"{label:24s} ({bins} bins, {pairs / 1e6:.1f} M pairs): forward {fwd * 1e3:8.2f} ms = "
              f"{pairs / fwd / 1e6:8.1f} M pairs/s | forward+backward {both * 1e3:8.2f} ms = "
              f"{pairs / both / 1e6:8.1f} M pairs/s | {base[0] / fwd:.2f}x / {base[1] / both:.2f}x one-thread")
    ext.configure(*before)


if __name__ == "__main__":
    main()
