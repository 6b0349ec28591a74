"""Real deep EXR files for tests: small ones bundled in tests/data (always present), larger optional ones.

`bundled(name)` is a file the project ships (tests/data, or examples/objectid.deep.exr); a missing one is a broken
checkout and fails loudly. `shared(name)` is a file from `shared/data/deep-real` beside the project (CI and the
development machine have it, a user's clone does not): a test that asks for it skips, with the reason, when the
folder is absent, and fails when the folder is there but the file is not.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
DATA = TESTS / "data"
SHARED = ROOT.parent / "shared" / "data" / "deep-real"
OBJECTID = ROOT / "examples" / "objectid.deep.exr"   # OpenEXR's objectid.deep.exr (examples/README.md)

# the deep files in tests/data, credited in tests/data/README.md
BUNDLED_FILES = ("LowResLeftView_Trunks.exr", "openexr_test_11.deep.exr", "openexr_test_42.deep.exr",
                 "openexrid_sample_motionblur_transparency.exr")
# deep files only ../shared holds (too large to bundle): optional extra cases
SHARED_ONLY_FILES = ("LeftView_Trunks.exr", "LowResLeftView_Balls.exr", "LowResLeftView_Leaves.exr",
                     "Stereo_Trunks.exr", "openexr_test_64.deep.exr", "openexr_test_multivariate.deep.exr")


def bundled(name: str) -> str:
    path = OBJECTID if name == OBJECTID.name else DATA / name
    assert path.is_file(), f"{path} is missing from the checkout (see tests/data/README.md)"
    return str(path)


def bundled_deep_files() -> list[str]:
    """Every bundled real deep file (never empty: a parametrization over it cannot silently vanish)."""
    return [bundled(n) for n in BUNDLED_FILES] + [str(OBJECTID)]


def shared(name: str) -> str:
    """A file of ../shared/data/deep-real; skips the calling test when that folder is absent."""
    if not SHARED.is_dir():
        pytest.skip(f"optional: {name} is only in {SHARED}, which is not beside this checkout "
                    "(the bundled tests/data files cover the same code)")
    path = SHARED / name
    assert path.is_file(), f"{SHARED} exists but has no {name}"
    return str(path)


def shared_params(names=SHARED_ONLY_FILES) -> list:
    """pytest params for optional files: each skips by itself (with the reason) when ../shared is absent."""
    marks = pytest.mark.skipif(not SHARED.is_dir(), reason=f"optional: {SHARED} is not beside this checkout")
    return [pytest.param(os.path.join(SHARED, n), id=n, marks=marks) for n in names]


def write_small_flat(path) -> str:
    """A real flat (scan-line, not deep) 8x6 half RGBA EXR written by the OpenEXR library itself."""
    import numpy as np
    import OpenEXR

    rgb = np.random.default_rng(0).random((6, 8, 3)).astype(np.float16)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": rgb, "A": np.ones((6, 8), np.float16)}).write(str(path))
    return str(path)
