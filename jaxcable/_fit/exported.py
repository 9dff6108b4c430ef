"""The fit kernel kept on disk as a traced and lowered program (`jax.export`).

JAX's persistent compilation cache saves a later process the XLA compilation of the
fit kernel, not its tracing and lowering through the solver's loop and the
simulation's scans, which is most of a warm `jaxcable fit`. Here the kernel
is exported once per static configuration (the model's structure and static fields,
the layout of the fitted parameters, the padded data's shapes and dtypes, the
solver, the number of starts and steps, the Jacobian's mode, the versions of
jaxcable's source, JAX and the platform), serialized under a hash of that
configuration, and a later process deserializes it and calls it (its compilation
then loads from the compilation cache).

Only the command line uses it (`cached_fit_kernels` around its call of
`jaxcable.fit`); the library's `jaxcable.fit` compiles `fit_kernel` as always. A
call that finds no program, or one it cannot read, exports and writes it, and runs
the exported program too, so that a run with an empty cache and a run that loads the
program run the same program and give bit-identical results.
"""

import contextlib
import contextvars
import dataclasses
import functools
import hashlib
import importlib.util
import os
import pathlib
import re
import tempfile
from typing import Any

import equinox as eqx
import jax
import optimistix as optx

from .solver import KernelMethod, KernelOut, fit_kernel


# The kernel `jaxcable.fit` calls: `fit_kernel`, unless `cached_fit_kernels` is in
# effect (a context variable, so that threads and nested calls keep their own).
_KERNEL = contextvars.ContextVar("jaxcable_fit_kernel", default=fit_kernel)
# Bump when the file format below changes, so that old files are ignored.
_FORMAT = 1
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def current_fit_kernel():
    """The fit kernel in effect: `fit_kernel`, or the cached one of
    `cached_fit_kernels`."""
    return _KERNEL.get()


@contextlib.contextmanager
def cached_fit_kernels(directory: str | os.PathLike):
    """Within the block, `jaxcable.fit` runs its kernel through programs exported to
    `directory` (read if there, else exported and written).

    **Arguments:**

    - `directory`: where the exported programs are kept (made when first needed).

    Without the `flatbuffers` package (JAX's serialization of exported programs
    needs it) the block changes nothing: the fits compile as usual.
    """
    if importlib.util.find_spec("flatbuffers") is None:
        yield
        return
    token = _KERNEL.set(functools.partial(_cached_call, pathlib.Path(directory)))
    try:
        yield
    finally:
        _KERNEL.reset(token)


@functools.cache
def _source_digest() -> str:
    """A hash of jaxcable's source files: an edited kernel is a new program."""
    root = pathlib.Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _fingerprint(static, treedef, leaves) -> str:
    """A hash of everything the traced program depends on besides the values of
    `leaves`: the static part of the arguments (their pytree structure and static
    fields, functions by qualified name), the leaves' shapes and dtypes, and the
    versions of the code and of JAX. Object addresses in reprs are dropped: they
    differ between processes, not between programs."""
    text = "\n".join(
        [
            f"format {_FORMAT}",
            _source_digest(),
            f"jax {jax.__version__}",
            f"backend {jax.default_backend()} {jax.devices()[0].device_kind}",
            # jax's Config sets its options as attributes at run time.
            f"x64 {jax.config.jax_enable_x64}",  # pyright: ignore[reportAttributeAccessIssue]
            _ADDRESS.sub("", str(treedef)),
            _ADDRESS.sub("", repr(jax.tree.leaves(static))),
            repr([(x.shape, str(x.dtype), _weak(x)) for x in leaves]),
        ]
    )
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _weak(x) -> bool:
    return bool(getattr(x, "weak_type", False))


def _avals(xs) -> list:
    return [(tuple(x.shape), str(x.dtype)) for x in xs]


def _split(problem, u_user, key, method: KernelMethod):
    """The fit kernel's arguments as (static, treedef, array leaves, key impl): the
    key goes in as its raw data (exported programs take plain arrays)."""
    args = (problem, u_user, jax.random.key_data(key), method.solver)
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree.flatten(dynamic)
    impl = str(jax.random.key_impl(key))
    settings = (method.max_steps, method.jac, method.num_starts, method.spread, impl)
    return (static, settings), treedef, leaves, jax.random.key_impl(key)


def _export(static, settings, treedef, leaves, impl):
    """Trace and lower the fit kernel for these arguments: (the exported program,
    the structure of its `KernelOut`)."""
    from jax import export  # only here: importing jaxcable need not load it

    max_steps, jac, num_starts, spread, _ = settings
    out_tree = []

    def flat_kernel(*leaves):
        dynamic = jax.tree.unflatten(treedef, leaves)
        problem, u_user, key_data, solver = eqx.combine(dynamic, static)
        key = jax.random.wrap_key_data(key_data, impl=impl)
        method = KernelMethod(solver, max_steps, jac, num_starts, spread)
        out = fit_kernel(problem, u_user, key, method)
        out_leaves, structure = jax.tree.flatten(out)
        out_tree.append(structure)
        return out_leaves

    exported = export.export(jax.jit(flat_kernel))(*leaves)
    return exported, out_tree[0]


def _out_structure(problem):
    """The pytree structure of the kernel's `KernelOut`, built on the host.

    (A pickled structure of equinox modules does not unflatten again, and tracing
    the kernel for it is what the cache saves.) Checked against the traced one
    before a program is written, so that a changed `KernelOut` turns the cache off
    instead of mis-assembling the output.
    """
    # Placeholder leaves: only the structure is read.
    fields: dict[str, Any] = {f.name: 0 for f in dataclasses.fields(KernelOut)}
    results = optx.RESULTS.successful
    fields.update(results=results, best_result=results, params=problem.base)
    return jax.tree.structure(KernelOut(**fields))


def _read(path: pathlib.Path):
    """The exported program in `path`, or None when it is missing or unreadable
    (then it is exported again and overwritten)."""
    from jax import export

    try:
        return export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # noqa: BLE001 - an unreadable file is a miss, not an error
        return None


def _write(path: pathlib.Path, exported) -> None:
    """Write atomically, so that a concurrent reader sees the whole file or none."""
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = bytes(exported.serialize())
    # Named like a cache entry, so that `jaxcable cache --clear` takes a file left
    # by an interrupted write too.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix="tmp-", suffix="-cache")
    with os.fdopen(fd, "wb") as f:
        f.write(blob)
    os.replace(tmp, path)


def _cached_call(
    directory: pathlib.Path,
    problem,
    u_user,
    key,
    method: KernelMethod,
) -> KernelOut:
    """`fit_kernel` through the exported program of its configuration."""
    static, treedef, leaves, impl = _split(problem, u_user, key, method)
    path = directory / f"fit-{_fingerprint(static, treedef, leaves)}-cache"
    structure = _out_structure(problem)
    exported = _read(path)
    if exported is not None and _avals(exported.in_avals) != _avals(leaves):
        exported = None  # not this configuration's program: export it again
    if exported is None:
        exported, traced = _export(*static, treedef, leaves, impl)
        if traced != structure:
            return fit_kernel(problem, u_user, key, method)
        _write(path, exported)
    return jax.tree.unflatten(structure, exported.call(*leaves))
