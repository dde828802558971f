"""The first-run notice: said once when a kernel compiles, its time reported after; silent on cache hits."""

import numba
from numba.core import event

from layerskin_exp.sim import compile_notice
from layerskin_exp.sim.compile_notice import _CompileNotice


def test_compile_is_announced_once_and_timed(capsys, monkeypatch):
    # a process-wide notice an earlier test installed (a simulated rig) would also speak when its
    # kernels came from the on-disk cache: only this test's notice listens here
    installed = compile_notice._NOTICE
    if installed is not None:
        event.unregister("numba:compile", installed)
        monkeypatch.setattr(compile_notice, "_NOTICE", None)
    notice = _CompileNotice()
    event.register("numba:compile", notice)
    try:
        @numba.njit
        def inner(x):
            return x * 2

        @numba.njit
        def outer(x):
            return inner(x) + 1

        assert outer(3) == 7  # outer compiles, and inner inside it: one top-level compilation
        assert outer(4) == 9  # compiled already: no event
        notice.report()
        notice.report()  # nothing new: silent
    finally:
        event.unregister("numba:compile", notice)
        if installed is not None:
            event.register("numba:compile", installed)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("compiling kernels, first run only")
    assert len(err) == 2 and err[1].startswith("compiled 1 kernel in ") and "first run only" in err[1]


def test_no_compilation_says_nothing(capsys):
    _CompileNotice().report()
    assert capsys.readouterr().err == ""
