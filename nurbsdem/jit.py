"""How the hot compiled kernels are compiled.

numba counts references to every array it handles (its runtime, NRT): each view a kernel
takes of a workspace row (``wf[_PA]``) or a shape table (``tab[6]``) is an atomic increment
and decrement, also inside a kernel called from a loop.  In the contact problem those atomic
operations take a large share of a warm LCP's time (the same bits without them), and two
threads share the shape tables' counters.  A kernel that creates no array needs no counts:
:func:`kernel` compiles it without the runtime.  A kernel that allocates (``np.zeros`` …)
keeps plain ``njit`` (numba refuses to compile an allocation here: the error names it).

Compile time (the first run after an install, an upgrade or an edit of a kernel's sources
compiles the kernels it calls; ``nurbsdem warmup`` does it ahead, :mod:`nurbsdem.warmup`).
numba finalises the machine code of every compiled function with all the functions it calls
linked in and optimised once more, so each layer between a large kernel and an entry point
compiles that kernel again.  The large kernels reached from several entry points (the LCP
of a pair and of a body against a wall, the neighbour list, the due rows, the step's parts,
the loop's evaluation and step control) are therefore called through function pointers
(:class:`PointerKernel`): compiled once per signature, and their callers hold an indirect
call.  Layers that only pass arrays on are ``njit(inline="always")`` (numba inlines their
IR: no machine code of their own), e.g. ``listed._solve_into``, ``detect.solve_rows``,
``deck_steps._search``.  A literal argument (``0``, ``False``, a module constant, also a
counter's ``n = 0`` before the loop raises it) gives the callee a second specialisation,
i.e. a second compilation: range bounds, body rows and counters go in as ``np.int64(0)``,
flags as ``np.bool_(False)``; the derivative order of the NURBS evaluation stays a literal
(each order compiles its own evaluation code).  Both keep the arithmetic, so the same bits
(docs/design-notes.md).
"""
from __future__ import annotations

import hashlib
import platform
import time
from functools import lru_cache
from typing import Callable

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils, config
from numba.extending import intrinsic


#: per-row passes (over bodies, contacts or listed pairs) of at least this many rows run on
#: numba's threads (``prange`` over chunks of :data:`ROW_CHUNK` rows:
#: :func:`nurbsdem.dynamics.integrator.drift`, the contact laws, the contact arrays ...);
#: shorter ones run on the calling thread, where a parallel launch would cost more than the
#: pass.  A pass is written once, as a loop over a range of rows (``lo``, ``hi``) that writes
#: only those rows' outputs: one call on the calling thread or one per chunk on the threads (a
#: function per row instead makes the contact loads several times slower: the call with its
#: ~30 array arguments, and numba's reference counts where the arrays pass through;
#: docs/design-notes.md).  Sums over rows stay in row order on one thread, so the bits depend
#: neither on this number nor on the thread count.
THREADED_ROWS = 4096
#: rows per chunk of a threaded pass
ROW_CHUNK = 1024


def launch_threads() -> None:
    """Start numba's threads (``numba.get_num_threads`` does), before compiled work: numba
    registers its thread scheduler's symbols only then, and a function compiled in a process
    without them may fail to link a cached kernel that calls a threaded pass (``LLVM ERROR:
    Symbol not found: allocate_sched``, an abort: seen once, a script's own ``njit`` function
    calling the cached ``contact_loads``, and not reproduced since).  The solver and
    :class:`~nurbsdem.dynamics.DemSystem` call it; the threads start at the first threaded
    pass anyway."""
    import numba
    numba.get_num_threads()


def kernel(func: Callable | None = None, *, inline: str = "never"):
    """``numba.njit(cache=True)`` without reference counting, for kernels that take views of
    arrays passed in but create none (usable bare, ``@kernel``, or ``@kernel(inline=...)``)."""
    jit = njit(cache=True, _nrt=False, inline=inline)
    return jit(func) if func is not None else jit


def internal(func: Callable | None = None, *, inline: str = "never"):
    """``numba.njit(cache=True)`` for a kernel that only other kernels call (usable bare or
    with ``inline=...``): numba builds no CPython or C entry for it.  Those entries unpack
    and box every argument; for the kernels that take the compiled loop's named tuples of
    arrays they are most of the kernel's compile time.  Such a kernel cannot be called from
    Python (the process would crash: there is no entry to call), so only private kernels
    of the compiled loop use it; ``tests/test_architecture.py`` checks that Python code of
    the package never calls one."""
    jit = njit(cache=True, inline=inline, no_cpython_wrapper=True, no_cfunc_wrapper=True)
    return jit(func) if func is not None else jit


#: the time-stamp counter is read only on x86-64 (on other CPUs the cycle counter may be
#: closed to user programs: reading it would raise SIGILL)
HAS_CYCLE_COUNTER = platform.machine().lower() in ("x86_64", "amd64")


if config.DISABLE_JIT:
    # plain Python (NUMBA_DISABLE_JIT=1, for debugging): an intrinsic has no Python form
    def cycles() -> int:
        """:func:`cycles` in plain Python: the ``time.perf_counter_ns`` clock."""
        return time.perf_counter_ns()

    def fetch_add(counter: np.ndarray, amount: int) -> int:
        """:func:`fetch_add` in plain Python (one thread: no atomics needed)."""
        before = int(counter[0])
        counter[0] += amount
        return before
else:
    @intrinsic
    def cycles(typingctx):
        """The CPU's cycle counter (int64; ``llvm.readcyclecounter``: the time-stamp counter on
        x86-64; 0 elsewhere), for timing parts of a compiled loop; :func:`seconds_per_cycle`
        converts."""
        def codegen(context, builder, signature, args):
            if not HAS_CYCLE_COUNTER:
                return ir.Constant(ir.IntType(64), 0)
            fn = cgutils.get_or_insert_function(builder.module,
                                                ir.FunctionType(ir.IntType(64), []),
                                                "llvm.readcyclecounter")
            return builder.call(fn, [])
        return types.int64(), codegen

    @intrinsic
    def fetch_add(typingctx, counter, amount):
        """Atomically add ``amount`` to ``counter[0]`` (a 1-d int64 array) and return its value
        before (``atomicrmw add``, monotonic): threads of a parallel loop taking chunks of work
        from a shared counter (:func:`nurbsdem.contact.detect.next_chunk`)."""
        if not (isinstance(counter, types.Array) and counter.dtype == types.int64
                and counter.ndim == 1 and isinstance(amount, types.Integer)):
            return None

        def codegen(context, builder, signature, args):
            ary = context.make_array(signature.args[0])(context, builder, args[0])
            ptr = cgutils.get_item_pointer(context, builder, signature.args[0], ary,
                                           [context.get_constant(types.intp, 0)])
            value = context.cast(builder, args[1], signature.args[1], types.int64)
            return builder.atomic_rmw("add", ptr, value, "monotonic")
        return types.int64(counter, amount), codegen


@njit(cache=True)
def _cycles_now() -> int:
    return cycles()


@lru_cache(maxsize=1)
def seconds_per_cycle() -> float:
    """Seconds per tick of :func:`cycles`, measured once against ``time.perf_counter`` over
    20 ms (0.0 where the platform has no counter: the compiled parts then report no time)."""
    c0, t0 = _cycles_now(), time.perf_counter()
    while time.perf_counter() - t0 < 0.02:
        pass
    c1, t1 = _cycles_now(), time.perf_counter()
    return (t1 - t0) / (c1 - c0) if c1 > c0 else 0.0


@njit(cache=True)
def n_chunks(n: int) -> int:
    """Chunks of :data:`ROW_CHUNK` rows that cover n rows."""
    return (n + ROW_CHUNK - 1) // ROW_CHUNK


@njit(cache=True)
def pack_chunks(buf: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The rows a threaded selection kept, packed to the front of ``buf`` (in place) in
    order: chunk t of :data:`ROW_CHUNK` rows wrote its ``counts[t]`` kept rows from
    ``buf[t · ROW_CHUNK]`` on (each chunk's rows in ascending order).  Returns buf[:kept],
    the rows a one-thread scan would have written.  Each chunk moves towards the front only,
    so chunk by chunk in order overwrites nothing still to be moved."""
    n = np.int64(0)
    for t in range(counts.shape[0]):
        lo = t * ROW_CHUNK
        for k in range(counts[t]):
            buf[n + k] = buf[lo + k]
        n += counts[t]
    return buf[:n]



class PointerKernel:
    """A kernel that other kernels call through a function pointer instead of linking it.

    numba finalises each compiled function with the machine code of every function it calls
    linked in and optimised again (module docstring), so a large kernel called from several
    entry points (the LCP of one pair, reached from the compiled loop, the Python path's
    ``solve_due``, the threaded batch ...) is optimised once per caller and again per layer
    between them.  Called through :attr:`call` instead, it is compiled once per signature and
    each caller holds only an indirect call.  The address sits in a process-wide slot, an
    LLVM global named after the kernel and a hash of its argument types
    (:meth:`symbol`), which llvmlite resolves when a caller is linked: the slot is made and
    filled (the kernel compiled or loaded from numba's cache) when a caller is typed, and,
    for a caller loaded from numba's cache, before its machine code is linked (numba's
    ``reload_init`` hooks of the caller's library).  The arithmetic is the kernel's own: the
    same bits as a direct call.

    ``kernel.call(a, b, ...)`` takes the kernel's arguments and returns what the kernel
    returns.  The arguments reach the call as numba's ``*args`` tuple, which counts no
    references: a tuple written at the call site (``call((a, b))``) would count every array of
    every named tuple in it up and down again, and in the compiled loop those counts were about
    a third of the code LLVM optimised.  With ``NUMBA_DISABLE_JIT=1`` it calls the Python function.

    ``lazy``: the kernel's slot stays empty until :func:`fill_lazy_kernels` of its group
    (``True``: "lcp") is called by a scene that needs it: the LCP kernels, which a scene of
    exact spheres never calls, the sphere–particle solver ("sphere_nurbs"), the mesh and
    surface walls' kernels ("curved") and the periodic cell's ("periodic"), which a scene
    without such pairs, walls or cell never calls, so that a first run does not compile them.  A call through an empty slot raises ``RuntimeError`` naming the kernel.
    A lazy kernel returns nothing, or what ``result(argtypes)`` declares (numba types): its
    callers are typed without compiling it, and the kernel compiled later must return exactly
    that (else ``TypeError``).

    :meth:`redirect` points every slot at another kernel of the same signatures and results
    (the force kernels' copies whose dispatch includes contact laws registered at run time,
    :func:`~nurbsdem.dynamics.laws.engine.engine_kernels`): callers already compiled or
    loaded call it from then on.
    """

    def __init__(self, dispatcher, name: str, lazy: bool | str = False,
                 result: Callable[[tuple], types.Type] | None = None) -> None:
        from numba.core import config

        self.dispatcher = dispatcher
        self.name = name
        #: the lazy group (None: not lazy)
        self.lazy = ("lcp" if lazy is True else lazy) or None
        #: the declared result type of a lazy kernel, from its argument types (None: nothing)
        self.result = result
        self._slots: dict[tuple, tuple] = {}
        #: the kernel the slots hold (:meth:`redirect`; the dispatcher's own by default)
        self.target = dispatcher
        _POINTER_KERNELS[name] = self
        if config.DISABLE_JIT:
            self.call = lambda *args: self.target(*args)
        else:
            self.call = _pointer_call(self)

    def redirect(self, target=None) -> None:
        """Put ``target`` (a kernel taking the same arguments and returning the same types;
        None: the kernel's own) in every slot, filled now and from now on."""
        target = self.dispatcher if target is None else target
        if target is self.target:
            return
        filled = {argtypes: self._compiled(target, argtypes, restype)
                  for argtypes, (slot, restype) in self._slots.items() if slot.value}
        self.target = target
        for argtypes, address in filled.items():
            self._slots[argtypes][0].value = address

    def _compiled(self, target, argtypes: tuple, restype):
        """The address of ``target`` compiled (or loaded) for ``argtypes``; a slot typed
        already (``restype`` not none) takes only a kernel of the same result type."""
        target.compile(argtypes)
        cres = target.overloads[argtypes]
        if restype != types.none and cres.signature.return_type != restype:
            raise TypeError(f"{target} returns {cres.signature.return_type}, not the "
                            f"{restype} of the pointer kernel {self.name}")
        return cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)

    def symbol(self, argtypes: tuple) -> str:
        """The name of the slot of the kernel compiled for ``argtypes``."""
        key = hashlib.sha1(str(tuple(argtypes)).encode()).hexdigest()[:16]
        return f"nurbsdem_kernel_{self.name}_{key}"

    def fill(self, argtypes: tuple):
        """Make the slot for ``argtypes`` (once per process) and, unless the kernel is lazy and
        no scene asked for lazy kernels yet, compile (or load) the kernel and put its address
        in it; returns the kernel's return type (none for a lazy kernel not compiled)."""
        import ctypes

        import llvmlite.binding as llb

        argtypes = tuple(argtypes)
        if argtypes not in self._slots:
            slot = ctypes.c_int64(0)
            llb.add_symbol(self.symbol(argtypes), ctypes.addressof(slot))
            declared = self.result(argtypes) if self.lazy and self.result else types.none
            self._slots[argtypes] = (slot, declared)
        slot, restype = self._slots[argtypes]
        if not slot.value and (self.lazy is None or self.lazy in _LAZY_WANTED):
            address = self._compiled(self.target, argtypes, restype)
            compiled = self.target.overloads[argtypes].signature.return_type
            if self.lazy is not None and compiled != restype:
                raise TypeError(f"the lazy pointer kernel {self.name} returns {compiled}, "
                                f"not the {restype} it declares")
            slot.value = address
            self._slots[argtypes] = (slot, compiled)
        return restype if self.lazy else self._slots[argtypes][1]

    def fill_all(self) -> None:
        """Fill the slot of every signature typed or loaded so far."""
        for argtypes in list(self._slots):
            self.fill(argtypes)


#: every :class:`PointerKernel` by name
_POINTER_KERNELS: dict[str, PointerKernel] = {}
#: the lazy groups :func:`fill_lazy_kernels` was called for in this process
_LAZY_WANTED: set[str] = set()


def fill_lazy_kernels(group: str = "lcp") -> None:
    """Fill the slots of the lazy :class:`PointerKernel` s of ``group`` (compiling or loading
    them), now and, for callers typed or loaded later, at once: "lcp" where a scene with
    bodies other than exact spheres is set up (:class:`~nurbsdem.contact.detect.ContactTable`),
    "sphere_nurbs" where the table also holds exact spheres, "curved" where the compiled
    deck steps take mesh or surface walls, "surface_particles"
    and "mesh_particles" where they take NURBS particles with surface or mesh walls,
    "periodic" where they take a periodic cell."""
    if group in _LAZY_WANTED:
        return
    _LAZY_WANTED.add(group)
    for pk in list(_POINTER_KERNELS.values()):
        if pk.lazy == group:
            pk.fill_all()


def _cached_libraries_keep_reload_hooks() -> None:
    """Make numba's kernels loaded from its cache keep their ``reload_init`` hooks on their
    code library, as freshly compiled ones do.  numba runs a cached kernel's hooks when it
    loads it, but leaves its library's set empty; a caller compiled later links that library
    and inherits its hooks from it, so without this a cached caller of a caller of a
    :class:`PointerKernel` would be linked before the pointer's slot exists (``LLVM ERROR:
    Symbol not found``)."""
    import inspect

    from numba.core import compiler

    rebuild = compiler.CompileResult._rebuild.__func__
    if getattr(rebuild, "_keeps_reload_hooks", False):
        return
    params = inspect.signature(rebuild)

    def _rebuild(cls, *args, **kwargs):
        cres = rebuild(cls, *args, **kwargs)
        reload_init = params.bind(cls, *args, **kwargs).arguments.get("reload_init")
        if reload_init:
            cres.library._reload_init.update(reload_init)
        return cres
    _rebuild._keeps_reload_hooks = True
    compiler.CompileResult._rebuild = classmethod(_rebuild)


_cached_libraries_keep_reload_hooks()


def _plain_shape_mismatch_errors() -> None:
    """Make an array assignment whose shapes differ (``a[i] = b``, ``a[:] = b``) raise numba's
    plain message ("cannot assign slice from input of different size", its generic targets')
    instead of one that formats both shapes.  The formatted message is compiled code of its
    own (string joins and integer formatting) for each pair of dimension counts, in each
    process, and linked into every kernel that assigns a row or a slice: it cost seconds per
    pair in a first run, for an error that only a bug in a kernel can raise.  The assignment
    itself is unchanged.  Where numba no longer has the overload this does nothing."""
    from numba.core.typing.templates import builtin_registry
    from numba.np import arrayobj

    def plain(src_shapes, index_shape):
        if (isinstance(src_shapes, types.UniTuple) and isinstance(index_shape, types.UniTuple)
                and src_shapes.dtype == index_shape.dtype
                and isinstance(src_shapes.dtype, types.Integer)):
            def impl(src_shapes, index_shape):
                raise ValueError("cannot assign slice from input of different size")
            return impl
        return None

    stub = getattr(arrayobj, "raise_with_shape_context", None)
    if stub is None:
        return
    for value, function_type in builtin_registry.globals:
        if value is not stub:
            continue
        for template in getattr(function_type, "templates", ()):
            func = getattr(template, "_overload_func", None)
            if getattr(func, "__name__", "") == "ol_raise_with_shape_context_cpu":
                template._overload_func = staticmethod(plain)


_plain_shape_mismatch_errors()


def _kernels_typed_without_literals() -> None:
    """Make a call from compiled code to one of the package's kernels compile the kernel for
    its arguments' plain types, as numba does for its own functions.  numba types a constant
    argument (``0``, ``True``, a module constant such as ``MAX_PER_WALL``) as its value
    (``Literal[int](0)``) and would compile the called kernel, with all it inlines, for that
    value as well as for the plain type that another caller (or the same loop's counter, once
    it changes) passes: one more compilation per constant in every first run.  The kernels
    compute the same with either type; kernels outside the package are left as numba types
    them."""
    from numba.core.types import functions

    get_call_type = functions.Dispatcher.get_call_type
    if getattr(get_call_type, "_plain_types", False):
        return

    def typed(self, context, args, kws):
        if self.dispatcher.py_func.__module__.startswith(__package__ + "."):
            args = tuple(types.unliteral(a) for a in args)
            kws = {k: types.unliteral(v) for k, v in kws.items()}
        return get_call_type(self, context, args, kws)
    typed._plain_types = True
    functions.Dispatcher.get_call_type = typed


_kernels_typed_without_literals()


def _reload_pointer(module: str, name: str, argtypes: tuple) -> None:
    """Fill the slot of kernel ``name`` of ``module`` for ``argtypes``: run by numba before it
    links a cached caller's machine code."""
    import importlib

    importlib.import_module(module)
    _POINTER_KERNELS[name].fill(argtypes)


def _pointer_call(pk: PointerKernel):
    """The intrinsic that calls ``pk``'s kernel through the address in its slot."""
    import functools

    module = pk.dispatcher.py_func.__module__

    @intrinsic
    def call(typingctx, *args):
        if len(args) == 1 and isinstance(args[0], (types.StarArgTuple, types.StarArgUniTuple)):
            args = tuple(args[0].types)       # typed again with the arguments packed
        argtypes = tuple(args)
        restype = pk.fill(argtypes)
        symbol = pk.symbol(argtypes)

        def codegen(context, builder, signature, llargs):
            context.active_code_library._reload_init.add(
                functools.partial(_reload_pointer, module, pk.name, argtypes))
            fnty = context.call_conv.get_function_type(restype, argtypes)
            slot = builder.module.globals.get(symbol)
            if slot is None:
                slot = ir.GlobalVariable(builder.module, ir.IntType(64), symbol)
                slot.linkage = "external"
            addr = builder.load(slot)
            with builder.if_then(builder.icmp_unsigned("==", addr, ir.Constant(addr.type, 0)),
                                 likely=False):
                context.call_conv.return_user_exc(
                    builder, RuntimeError, (f"compiled kernel {pk.name} not loaded",))
            values = [builder.extract_value(llargs[0], i) for i in range(len(argtypes))]
            status, res = context.call_conv.call_function(
                builder, builder.inttoptr(addr, fnty.as_pointer()), restype, argtypes, values)
            with cgutils.if_unlikely(builder, status.is_error):
                context.call_conv.return_status_propagate(builder, status)
            return res
        return restype(types.StarArgTuple(argtypes)), codegen
    return call
