"""The ``ranad`` click group: global options and the one place where errors become exit codes.

A RanadError (bad input, unwritable output) is printed as one line ``ranad: error: <file>: <problem>`` and
exits with 2, as does running out of memory; any other exception is an internal error (exit 1). Tracebacks
appear only with ``--debug``.
The handling lives in the group's ``invoke`` so click's CliRunner sees exactly what a shell user sees.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import traceback

# torch's request for transparent huge pages (THP_MEM_ALLOC_ENABLE=1) is left off. It made the RaNA kernels' own
# benchmark faster (bench/rana.py, forward+backward at 512x512: 1.89 s against 2.14 s when it was adopted; 117
# against 108 M pairs/s on a 2-core AVX-512 VM in session 37), where buffers are reused, but a denoise touches most
# of its memory once, and on such a VM each fresh huge page took milliseconds to fault in (the host backs it 4 KB
# at a time): the held-out 1080p frame (`ranad denoise F --profile`, F from bench/denoise.py --frame) 24.3-24.8 s
# without it against 25.5-26.1 s with it (three runs each, alternating; system time 1.9-2.2 s against 4.4-4.8 s),
# and 40 training steps 25.0-25.8 s against 27.1-27.5 s. A user's own setting is read by torch as before.
# numpy's own request for huge pages (madvise on every array of 4 MB or more) did the opposite on a 2-core AVX-512
# VM: faulting in a fresh 221 MB array took 0.42 s against 0.09 s without it, and the held-out 1080p frame
# (`ranad denoise F --profile`, F from bench/denoise.py --frame) 30.0 s against 28.0 s. Read when numpy is first
# imported, so set here, before anything imports it; a user's own setting wins.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
# numpy's BLAS (OpenBLAS; torch has its own) serves only small products here ([N, 3] colours times luminance
# weights), yet its threads busy-wait after each one on the cores torch's threads need: 2% of a denoise's samples
# (perf, the 512x512 crop of bench/denoise.py's frame). One thread: no pool to spin. Read when numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


from ranad_core import heap  # noqa: E402

# the layers' tensors reuse freed pages instead of faulting in fresh ones; before anything allocates (heap.py)
heap.keep_freed_memory()

import click

from ranad_core import __version__
from ranad_core.errors import RanadError
from ranad_core.fileutil import Terminated

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1


def _terminate(signum, frame):
    raise Terminated()


class RanadGroup(click.Group):
    def invoke(self, ctx: click.Context):
        previous = None
        with contextlib.suppress(ValueError):   # signals can be set in the main thread only
            previous = signal.signal(signal.SIGTERM, _terminate)
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            raise
        except RanadError as e:
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            click.echo(f"ranad: error: {e}", err=True)
            ctx.exit(EXIT_USER_ERROR)
        except KeyboardInterrupt:
            click.echo("ranad: interrupted", err=True)
            ctx.exit(130)
        except Terminated:   # a farm stopping the job: the temporary files are gone (atomic_output)
            click.echo("ranad: terminated", err=True)
            ctx.exit(128 + signal.SIGTERM)
        except BrokenPipeError:   # `ranad info F | head`: the reader left; no traceback, and none at exit either
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            ctx.exit(EXIT_INTERNAL_ERROR)
        except MemoryError as e:   # a frame larger than the memory the process may have (ulimit, a farm's cap)
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            click.echo(f"ranad: error: out of memory ({e or 'no detail'}): the input needs more memory than this "
                       f"process could get", err=True)
            ctx.exit(EXIT_USER_ERROR)
        except Exception as e:  # noqa: BLE001 - the CLI boundary turns every failure into an exit code
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            else:
                click.echo(f"ranad: internal error: {type(e).__name__}: {e} (rerun with --debug for details)",
                           err=True)
            ctx.exit(EXIT_INTERNAL_ERROR)
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)


@click.group(cls=RanadGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="ranad")
@click.option("--io", "io_mode", type=click.Choice(["auto", "oiio", "fast"]), default="auto", show_default=True,
              help="Deep EXR I/O path: 'fast' is ranad's vectorised codec, 'oiio' forces OpenImageIO "
                   "(slow, for files the fast codec should not touch), 'auto' uses fast where it applies.")
@click.option("--debug", is_flag=True, help="Show Python tracebacks on errors.")
@click.pass_context
def cli(ctx: click.Context, io_mode: str, debug: bool) -> None:
    """ranad: denoise deep EXR renders (deep-Z and deep-OID) while keeping their bins.

    \b
    Commands:
      info     what is in a deep EXR file (parts, channels, bins per pixel, ...)
      flatten  composite deep EXRs into flat EXR/PNG/JPEG images for review
    """
    from ranad_core import exr

    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug
    exr.set_io_mode(io_mode)


from .cmd_aov import aov_cmd  # noqa: E402  (commands import nothing from this module)
from .cmd_denoise import denoise_cmd  # noqa: E402
from .cmd_eval import eval_cmd  # noqa: E402
from .cmd_export import export_cmd  # noqa: E402
from .cmd_flatten import flatten_cmd  # noqa: E402
from .cmd_info import info_cmd  # noqa: E402
from .cmd_synth import synth_cmd  # noqa: E402
from .cmd_train import train_cmd  # noqa: E402

cli.add_command(info_cmd)
cli.add_command(flatten_cmd)
cli.add_command(synth_cmd)
cli.add_command(train_cmd)
cli.add_command(eval_cmd)
cli.add_command(denoise_cmd)
cli.add_command(aov_cmd)
cli.add_command(export_cmd)


def main() -> None:
    cli(prog_name="ranad")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
