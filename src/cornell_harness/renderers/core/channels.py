"""Kernels written once over a channel type, compiled by numba once per type.

The path tracer's bounce kernel runs on RGB paths (3 channels) and on
hero-wavelength paths (4 wavelengths), as pbrt-v4's ``PathIntegrator`` runs
on ``SampledSpectrum``. What differs between the two (where a path keeps its
throughput, how a reflectance or an emission is looked up for it, how its
channels reach the pixel's RGB) is a handful of small *channel functions*,
written once per channel type as the functions of a class
(:class:`cornell_harness.renderers.pathtracer.RGB`,
:class:`cornell_harness.renderers.hero_wavelength.Hero`). The kernel calls
each by one name, made by :func:`channel_functions`: a numba overload that
picks the implementation by the type of its first argument, the path state
(a NamedTuple per channel type), when numba compiles the kernel. Each path
state type gets its own compiled kernel with the chosen bodies inlined into
it: nothing is dispatched at run time, and the kernel is an ordinary
module-level ``jit`` function, so numba's on-disk cache keeps it.

Keep a channel function straight-line code (a loop of fixed length is fine,
and so is calling a function of scalars that branches) and the decisions in
the kernel: once inlined, a channel function that branches gets an atomic
reference-count update of every array of the tuples it is passed (the path
state, the scene's tables) at every call, which numba's pruning of them does
not remove. The whole NEE step
(:func:`cornell_harness.renderers.core.direct.light_sample` and its colour)
as one channel function made the hero renders markedly slower
(BENCHMARKS.md); the kernel calls ``light_sample`` itself and leaves only
the colour to the channel type.

The other ways numba offers, and why not them:

- a kernel factory (a Python function that builds the ``jit`` kernel as a
  closure over per-type helper kernels): numba keys a closure's cache entry
  on its pickled closed-over values, and a pickled dispatcher carries a uuid
  drawn per process, so a factory-made kernel is never found in the cache.
  It would compile at every process start (about a minute of CPU), which
  ``scripts/compile_kernels.py`` exists to avoid, and add an index entry
  each time;
- first-class function types (the helpers passed as arguments): an indirect
  call per channel function, which numba cannot inline;
- ``isinstance`` on the path state inside the kernel: numba's ``isinstance``
  does not take NamedTuples; ``generated_jit`` is gone from numba.
"""

from __future__ import annotations

import inspect
from typing import Callable, Sequence

from numba.extending import overload

#: The options of :data:`cornell_harness.renderers.core.sampling.jit` that change code; the bodies are inlined
#: into a kernel compiled with them, and any body numba compiles alone gets them too.
_JIT_OPTIONS = {"nogil": True, "error_model": "numpy"}


def channel_functions(types: dict[type, type], names: Sequence[str]) -> tuple[Callable, ...]:
    """One kernel-callable function per name: ``name(state, ...)`` runs ``types[type(state)].name(state, ...)``.

    ``types`` maps each path state type (a NamedTuple class) to its channel type, a class whose attributes
    ``names`` are ``jit`` functions with the same parameters in every channel type (the first: the state).
    Called from Python, the functions raise TypeError: they exist only in compiled kernels.
    """
    return tuple(_channel_function(name, {state: getattr(ops, name) for state, ops in types.items()})
                 for name in names)


def _channel_function(name: str, impls: dict) -> Callable:
    bodies = {state: impl.py_func for state, impl in impls.items()}
    params = {str(inspect.signature(f)) for f in bodies.values()}
    assert len(params) == 1, f"channel function {name}: its implementations' parameters differ: {sorted(params)}"

    def function(*args):
        raise TypeError(f"{name} is a channel function: it runs inside numba kernels only")

    function.__name__ = function.__qualname__ = name

    def resolve(*args):
        return bodies.get(getattr(args[0], "instance_class", None))

    # numba requires the implementation's parameters to be the typing function's.
    resolve.__signature__ = inspect.signature(next(iter(bodies.values())))
    overload(function, inline="always", jit_options=_JIT_OPTIONS)(resolve)
    return function
