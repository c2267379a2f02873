"""scikit-sparse 0.4.x's ``Factor`` inside a reference cycle: empty its ``tp_clear`` slot.

The one place posecrb reaches into another library's C-level data; docs/decisions/sksparse-factor-gc.md
records the defect, what it does unrepaired, the alternatives weighed and why this remains.

The defect (sksparse/cholmod.pyx, 0.4.16, the same since 0.4.1): ``Factor`` holds
``cdef readonly Common _common``, and its ``__dealloc__`` frees the CHOLMOD factor with
``cholmod_free_factor(&self._factor, &self._common._common)``. Because ``_common`` is a Python
object field, Cython gives the type a ``tp_clear`` that sets it to ``None``. When a Factor dies
inside a reference cycle (an exception's traceback holding the frame that holds the factor, a
result object referring to itself), the cyclic garbage collector may call that ``tp_clear`` first;
``__dealloc__`` then reads ``_common`` fields from the memory after ``None`` (Cython does not check
for ``None`` there) and hands CHOLMOD a ``cholmod_common`` pointer into the interpreter's static
data. CHOLMOD writes its status there (-4, ``CHOLMOD_INVALID``): the interpreter's memory is
corrupted and the factor's memory leaks. Cython's cure is the ``no_gc_clear`` directive, which
0.4.x lacks; 0.5 and later need SuiteSparse >= 7, which Debian 12 does not ship.

The repair: the slot is emptied. The garbage collector then breaks such cycles at their other
objects, and the Factor is deallocated by reference count with its Common intact. The slot's
address is checked against ``PyType_GetSlot`` before anything is written; on an interpreter whose
type layout differs nothing is changed (and a scikit-sparse built with ``no_gc_clear`` has no
slot to empty: nothing is written either). tests/linalg/test_cholesky.py reproduces the corruption without
this module and checks it does not occur with it.
"""
from __future__ import annotations

import ctypes
import logging

log = logging.getLogger("posecrb")

_PY_TP_CLEAR = 51                                  # Include/typeslots.h


def disable_gc_clear(tp: type) -> bool:
    """Empty the ``tp_clear`` slot of the Cython type ``tp`` (module docstring); returns whether the
    slot is empty afterwards."""
    get_slot = ctypes.pythonapi.PyType_GetSlot
    get_slot.restype, get_slot.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_int]
    try:
        current = get_slot(tp, _PY_TP_CLEAR)
    except SystemError:                            # static types before Python 3.10
        return False
    if not current:
        return True

    class _TypeHead(ctypes.Structure):             # PyTypeObject up to tp_clear (Include/cpython/object.h)
        _fields_ = [("ob_refcnt", ctypes.c_ssize_t), ("ob_type", ctypes.c_void_p), ("ob_size", ctypes.c_ssize_t),
                    ("tp_name", ctypes.c_char_p), ("tp_basicsize", ctypes.c_ssize_t),
                    ("tp_itemsize", ctypes.c_ssize_t)]
        _fields_ += [(f"slot{k}", ctypes.c_void_p) for k in range(15)]   # tp_dealloc .. tp_as_buffer
        _fields_ += [("tp_flags", ctypes.c_ulong), ("tp_doc", ctypes.c_char_p), ("tp_traverse", ctypes.c_void_p),
                     ("tp_clear", ctypes.c_void_p)]

    head = _TypeHead.from_address(id(tp))
    if head.tp_clear != current or head.tp_basicsize != tp.__basicsize__:
        log.debug("%s: unexpected type layout, tp_clear left in place", tp.__name__)
        return False
    head.tp_clear = None
    return True


__all__ = ["disable_gc_clear"]
