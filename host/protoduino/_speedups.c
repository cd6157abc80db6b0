/*
 * protoduino._speedups: the host's stream decoder in C (its speed: docs/performance.md).
 *
 * framing.PyStreamDecoder is the reference; this type must give exactly what
 * it gives: the same Packet / BadFrame items (instances of the classes in
 * protoduino.packets, PacketType members for `type`), the same reasons and
 * raw bytes, the same `counts` updates, whatever the chunking, with the same
 * bounded memory. tests/unit/test_framing_props.py holds both to a plain
 * byte-at-a-time reference.
 *
 * Why C: in pure Python the per-frame interpreter work (a call into the
 * `cobs` package, the CRC call, the checks, building the tuple) is the cost,
 * and a short-frame protocol pays it for every 15 bytes. Here one call splits
 * a whole read, and per frame only the output objects remain.
 *
 * COBS and CRC come from the firmware's own portable core (pd_cobs.c,
 * pd_crc.c) compiled into this module: the host checks frames with the very
 * code the device uses, and pd_protocol.h supplies the sizes.
 *
 * The recovery policy is framing.py's (its module docstring): act only at a
 * 0x00; drop and count a frame that fails COBS, LEN, CRC or TYPE; a run of
 * more than PD_MAX_ENCODED_FRAME bytes is an overflow, reported once with its
 * first PD_MAX_ENCODED_FRAME + 1 bytes, then skipped up to the next 0x00.
 *
 * Python's limited API of 3.11 (the stable ABI, abi3): one build serves every
 * CPython from 3.11 on (Debian 12's 3.11, Debian 13's and Raspberry Pi OS's
 * 3.13), so a wheel is per machine kind, not per Python version (setup.py).
 * The type is made from a spec at import; module globals (single-phase init):
 * the module is loaded once per process by framing.py and holds nothing but
 * immutable references.
 *
 * Under AddressSanitizer, by hand (Python itself is not instrumented, hence
 * the preload and the system allocator so that ASan sees object memory):
 *   gcc -std=c99 -g -O1 -fsanitize=address,undefined -fPIC -shared \
 *       -Ifirmware/core -I$(python -c 'import sysconfig; print(sysconfig.get_paths()["include"])') \
 *       host/protoduino/_speedups.c firmware/core/pd_cobs.c firmware/core/pd_crc.c \
 *       -o COPY_OF_THE_PACKAGE/protoduino/_speedups$(python3-config --extension-suffix)
 *   PYTHONPATH=COPY_OF_THE_PACKAGE PYTHONMALLOC=malloc ASAN_OPTIONS=detect_leaks=0 \
 *   LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)" \
 *       python -m pytest tests/unit/test_framing_props.py
 */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030B0000
#include <Python.h>
#include <structmember.h>

#include <stdint.h>
#include <string.h>

#include "pd_cobs.h"
#include "pd_crc.h"
#include "pd_protocol.h"

#ifndef PD_SPEEDUPS_DIGEST
#define PD_SPEEDUPS_DIGEST "unknown"
#endif

/* Why a frame was dropped, then good packets: the keys of `counts`. */
enum pd_reason {
    PD_R_COBS,
    PD_R_CRC,
    PD_R_LENGTH,
    PD_R_TYPE,
    PD_R_OVERFLOW,
    PD_R_PACKETS,
    PD_R_COUNT
};

static const char *const pd_reason_names[PD_R_COUNT] = {
    "cobs", "crc", "length", "type", "overflow", "packets",
};

/*
 * CRC-16/CCITT-FALSE a byte at a time from a table. The firmware's bitwise
 * pd_crc16_update (no table: flash is scarce on the Uno) took 45 % of this
 * module's time per frame under perf; here each entry is pd_crc16_update's
 * own result for one byte from a zero register, so the firmware's code still
 * defines the CRC, and PyInit checks both agree on the standard check value.
 */
static uint16_t pd_crc_table[256];

static void pd_crc_table_init(void)
{
    for (unsigned i = 0; i < 256; i++) {
        const uint8_t byte = (uint8_t)i;
        pd_crc_table[i] = pd_crc16_update(0, &byte, 1);
    }
}

static uint16_t pd_crc16_fast(const uint8_t *data, size_t len)
{
    uint16_t crc = PD_CRC16_INIT;
    for (size_t i = 0; i < len; i++) {
        crc = (uint16_t)((crc << 8) ^ pd_crc_table[(uint8_t)((crc >> 8) ^ data[i])]);
    }
    return crc;
}

/* References taken at import and held for the life of the process. */
static PyTypeObject *pd_packet_cls;      /* protoduino.packets.Packet */
static PyTypeObject *pd_badframe_cls;    /* protoduino.packets.BadFrame */
static allocfunc pd_packet_alloc;        /* their tp_alloc slots */
static allocfunc pd_badframe_alloc;
static PyObject *pd_reason_str[PD_R_COUNT];
static PyObject *pd_packet_types[256];   /* PacketType member by TYPE byte, or NULL */

typedef struct {
    PyObject_HEAD
    PyObject *counts; /* a collections.Counter, as in the Python decoder */
    size_t buf_len;   /* bytes of the partial frame in buf */
    int skipping;     /* an overflowed frame is skipped up to the next 0x00 */
    uint8_t buf[PD_MAX_ENCODED_FRAME];
} pd_decoder;

/*
 * What one feed() call tallies. The Python decoder bumps a drop reason's
 * count as it meets each bad frame, "packets" once after the frames of a
 * read, and a tail overflow last; keys are applied here in the order they
 * first occurred, so even the Counter's key order matches.
 */
typedef struct {
    Py_ssize_t n[PD_R_COUNT];
    int order[PD_R_COUNT];
    int n_order;
} pd_tally;

static void pd_tally_add(pd_tally *t, int reason, Py_ssize_t k)
{
    if (t->n[reason] == 0) {
        t->order[t->n_order++] = reason;
    }
    t->n[reason] += k;
}

/*
 * A Packet or BadFrame: what tuple.__new__(cls, items) does for a tuple
 * subclass, without the Python-level call. PyInit checks that both classes
 * are plain tuple subclasses (NamedTuples with no extra storage). Steals
 * the references in `items` even on failure.
 */
static PyObject *pd_new_tuple(PyTypeObject *cls, PyObject **items, Py_ssize_t n)
{
    allocfunc alloc = cls == pd_packet_cls ? pd_packet_alloc : pd_badframe_alloc;
    PyObject *obj = alloc(cls, n);
    if (obj == NULL) {
        for (Py_ssize_t i = 0; i < n; i++) {
            Py_XDECREF(items[i]);
        }
        return NULL;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        /* A fresh tuple (refcount 1): cannot fail, and steals items[i]. */
        (void)PyTuple_SetItem(obj, i, items[i]);
    }
    return obj;
}

/* Append BadFrame(reason, raw[:len]) to out. Returns 0, or -1 with an exception set. */
static int pd_emit_bad(PyObject *out, pd_tally *t, int reason, const uint8_t *raw, size_t len)
{
    PyObject *items[2];
    PyObject *item;
    int rc;

    items[1] = PyBytes_FromStringAndSize((const char *)raw, (Py_ssize_t)len);
    if (items[1] == NULL) {
        return -1;
    }
    Py_INCREF(pd_reason_str[reason]);
    items[0] = pd_reason_str[reason];
    item = pd_new_tuple(pd_badframe_cls, items, 2);
    if (item == NULL) {
        return -1;
    }
    rc = PyList_Append(out, item);
    Py_DECREF(item);
    if (rc == 0) {
        pd_tally_add(t, reason, 1);
    }
    return rc;
}

/* One complete frame (1..PD_MAX_ENCODED_FRAME bytes, no delimiter) to an item in out. */
static int pd_emit_frame(PyObject *out, pd_tally *t, const uint8_t *enc, size_t len)
{
    uint8_t raw[PD_MAX_ENCODED_FRAME]; /* decoding never grows a frame */
    PyObject *items[3];
    PyObject *item;
    PyObject *ptype;
    int size;
    int rc;

    size = pd_cobs_decode(enc, len, raw, sizeof raw);
    if (size < 0) {
        return pd_emit_bad(out, t, PD_R_COBS, enc, len);
    }
    if (size < PD_MIN_PACKET || size != PD_MIN_PACKET + raw[1]) {
        return pd_emit_bad(out, t, PD_R_LENGTH, enc, len);
    }
    /* The CRC over data and its own big-endian CRC is zero. */
    if (pd_crc16_fast(raw, (size_t)size) != 0) {
        return pd_emit_bad(out, t, PD_R_CRC, enc, len);
    }
    ptype = pd_packet_types[raw[0]];
    if (ptype == NULL) {
        return pd_emit_bad(out, t, PD_R_TYPE, enc, len);
    }
    items[2] = PyBytes_FromStringAndSize((const char *)raw + PD_HEADER_SIZE,
                                         size - PD_MIN_PACKET);
    if (items[2] == NULL) {
        return -1;
    }
    items[1] = PyLong_FromLong(raw[2]);
    if (items[1] == NULL) {
        Py_DECREF(items[2]);
        return -1;
    }
    Py_INCREF(ptype);
    items[0] = ptype;
    item = pd_new_tuple(pd_packet_cls, items, 3);
    if (item == NULL) {
        return -1;
    }
    rc = PyList_Append(out, item);
    Py_DECREF(item);
    if (rc == 0) {
        t->n[PD_R_PACKETS]++; /* placed in the key order after the frames, see pd_feed */
    }
    return rc;
}

/* counts[key] += n for each tallied key, in first-occurrence order. */
static int pd_apply_tally(pd_decoder *self, const pd_tally *t)
{
    if (t->n_order == 0) {
        return 0;
    }
    if (self->counts == NULL) {
        PyErr_SetString(PyExc_AttributeError, "StreamDecoder has no attribute 'counts'");
        return -1;
    }
    /* The Counter may run Python code; hold it in case that code replaces it. */
    PyObject *counts = self->counts;
    Py_INCREF(counts);
    int rc = 0;
    for (int i = 0; i < t->n_order && rc == 0; i++) {
        PyObject *key = pd_reason_str[t->order[i]];
        PyObject *old = PyObject_GetItem(counts, key); /* Counter.__missing__ gives 0 */
        PyObject *add = NULL;
        PyObject *sum = NULL;
        rc = -1;
        if (old != NULL && (add = PyLong_FromSsize_t(t->n[t->order[i]])) != NULL &&
            (sum = PyNumber_Add(old, add)) != NULL) {
            rc = PyObject_SetItem(counts, key, sum);
        }
        Py_XDECREF(old);
        Py_XDECREF(add);
        Py_XDECREF(sum);
    }
    Py_DECREF(counts);
    return rc;
}

/*
 * The decoder's state (buf, buf_len, skipping) is consistent whenever Python
 * code can run (an allocation may trigger the garbage collector and a
 * finalizer): a joined frame is copied out of buf and buf emptied before any
 * object is built, so even a misuse such as feeding the same decoder from
 * two threads cannot make it read or write out of bounds.
 */
static PyObject *pd_feed(pd_decoder *self, const uint8_t *p, const uint8_t *end)
{
    /* A frame joined from the partial buffer and this read, up to one byte past the limit. */
    uint8_t joined[PD_MAX_ENCODED_FRAME + 1];
    pd_tally t;
    PyObject *out = PyList_New(0);

    if (out == NULL) {
        return NULL;
    }
    memset(&t, 0, sizeof t);
    while (p < end) {
        const uint8_t *z = memchr(p, 0, (size_t)(end - p));
        size_t seg;
        int rc = 0;

        if (z == NULL) {
            break;
        }
        seg = (size_t)(z - p);
        if (self->skipping) {
            /* This delimiter ends the frame that overflowed. */
            self->skipping = 0;
        } else if (self->buf_len > 0) {
            size_t have = self->buf_len;
            size_t take = seg;
            if (take > sizeof joined - have) {
                take = sizeof joined - have;
            }
            memcpy(joined, self->buf, have);
            memcpy(joined + have, p, take);
            self->buf_len = 0;
            if (have + seg > PD_MAX_ENCODED_FRAME) {
                rc = pd_emit_bad(out, &t, PD_R_OVERFLOW, joined, sizeof joined);
            } else {
                rc = pd_emit_frame(out, &t, joined, have + seg);
            }
        } else if (seg > PD_MAX_ENCODED_FRAME) {
            rc = pd_emit_bad(out, &t, PD_R_OVERFLOW, p, PD_MAX_ENCODED_FRAME + 1);
        } else if (seg > 0) { /* lone delimiters (empty frames) are ignored */
            rc = pd_emit_frame(out, &t, p, seg);
        }
        if (rc < 0) {
            Py_DECREF(out);
            return NULL;
        }
        p = z + 1;
    }
    if (t.n[PD_R_PACKETS] > 0) {
        t.order[t.n_order++] = PD_R_PACKETS;
    }
    if (p < end && !self->skipping) {
        size_t tail = (size_t)(end - p);
        size_t have = self->buf_len;
        if (have + tail > PD_MAX_ENCODED_FRAME) {
            /* Discard at once (bounded memory) and skip to the next delimiter. */
            memcpy(joined, self->buf, have);
            memcpy(joined + have, p, sizeof joined - have);
            self->buf_len = 0;
            self->skipping = 1;
            if (pd_emit_bad(out, &t, PD_R_OVERFLOW, joined, sizeof joined) < 0) {
                Py_DECREF(out);
                return NULL;
            }
        } else {
            memcpy(self->buf + have, p, tail);
            self->buf_len = have + tail;
        }
    }
    if (pd_apply_tally(self, &t) < 0) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

/* Like the Python decoder's bytes(data): any buffer, and whatever bytes() accepts besides. */
static PyObject *pd_decoder_feed(pd_decoder *self, PyObject *data)
{
    Py_buffer view;
    PyObject *copy = NULL;
    PyObject *out;

    if (PyObject_GetBuffer(data, &view, PyBUF_SIMPLE) < 0) {
        /* Not a contiguous buffer (a strided memoryview, a list of ints): copy it. */
        if (!PyErr_ExceptionMatches(PyExc_BufferError) &&
            !PyErr_ExceptionMatches(PyExc_TypeError)) {
            return NULL;
        }
        PyErr_Clear();
        copy = PyBytes_FromObject(data);
        if (copy == NULL) {
            return NULL;
        }
        if (PyObject_GetBuffer(copy, &view, PyBUF_SIMPLE) < 0) {
            Py_DECREF(copy);
            return NULL;
        }
    }
    /* A bytearray cannot be resized while its buffer is held, so view stays valid. */
    out = pd_feed(self, (const uint8_t *)view.buf, (const uint8_t *)view.buf + view.len);
    PyBuffer_Release(&view);
    Py_XDECREF(copy);
    return out;
}

static PyObject *pd_decoder_feed_all(pd_decoder *self, PyObject *chunks)
{
    PyObject *it = PyObject_GetIter(chunks);
    PyObject *out;
    PyObject *chunk;

    if (it == NULL) {
        return NULL;
    }
    out = PyList_New(0);
    if (out == NULL) {
        Py_DECREF(it);
        return NULL;
    }
    while ((chunk = PyIter_Next(it)) != NULL) {
        PyObject *items = pd_decoder_feed(self, chunk);
        Py_DECREF(chunk);
        if (items == NULL ||
            PyList_SetSlice(out, PyList_Size(out), PyList_Size(out), items) < 0) {
            Py_XDECREF(items);
            Py_DECREF(out);
            Py_DECREF(it);
            return NULL;
        }
        Py_DECREF(items);
    }
    Py_DECREF(it);
    if (PyErr_Occurred()) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

static PyObject *pd_decoder_reset(pd_decoder *self, PyObject *Py_UNUSED(ignored))
{
    self->buf_len = 0;
    self->skipping = 0;
    Py_RETURN_NONE;
}

static PyObject *pd_counter_cls; /* collections.Counter */
static PyObject *pd_decoder_type; /* StreamDecoder, made from pd_decoder_spec at import */

static int pd_decoder_init(pd_decoder *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {NULL};
    PyObject *counts;

    if (!PyArg_ParseTupleAndKeywords(args, kwargs, ":StreamDecoder", kwlist)) {
        return -1;
    }
    counts = PyObject_CallNoArgs(pd_counter_cls);
    if (counts == NULL) {
        return -1;
    }
    self->buf_len = 0;
    self->skipping = 0;
    Py_XDECREF(self->counts);
    self->counts = counts;
    return 0;
}

static int pd_decoder_traverse(pd_decoder *self, visitproc visit, void *arg)
{
    /* An instance of a heap type holds a reference to its type (Python >= 3.9). */
    Py_VISIT(Py_TYPE((PyObject *)self));
    Py_VISIT(self->counts);
    return 0;
}

static int pd_decoder_clear(pd_decoder *self)
{
    Py_CLEAR(self->counts);
    return 0;
}

/* The instance's reference to its heap type is dropped here, after the memory is freed. */
static void pd_decoder_dealloc(pd_decoder *self)
{
    PyTypeObject *type = Py_TYPE((PyObject *)self);
    freefunc tp_free = (freefunc)PyType_GetSlot(type, Py_tp_free);

    PyObject_GC_UnTrack(self);
    pd_decoder_clear(self);
    tp_free(self);
    Py_DECREF(type);
}

static PyMethodDef pd_decoder_methods[] = {
    {"feed", (PyCFunction)pd_decoder_feed, METH_O,
     "feed(data) -> list[Packet | BadFrame]: the items completed by this chunk."},
    {"feed_all", (PyCFunction)pd_decoder_feed_all, METH_O,
     "feed_all(chunks) -> list[Packet | BadFrame]: feed each chunk in turn."},
    {"reset", (PyCFunction)pd_decoder_reset, METH_NOARGS,
     "Forget any partial frame (the link was reset)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef pd_decoder_members[] = {
    {"counts", T_OBJECT_EX, offsetof(pd_decoder, counts), 0,
     "collections.Counter of 'packets' and each drop reason."},
    {NULL, 0, 0, 0, NULL},
};

static PyType_Slot pd_decoder_slots[] = {
    {Py_tp_doc, "Incremental COBS stream decoder in C, equivalent to framing.PyStreamDecoder."},
    {Py_tp_new, PyType_GenericNew},
    {Py_tp_init, pd_decoder_init},
    {Py_tp_dealloc, pd_decoder_dealloc},
    {Py_tp_traverse, pd_decoder_traverse},
    {Py_tp_clear, pd_decoder_clear},
    {Py_tp_methods, pd_decoder_methods},
    {Py_tp_members, pd_decoder_members},
    {0, NULL},
};

static PyType_Spec pd_decoder_spec = {
    .name = "protoduino._speedups.StreamDecoder",
    .basicsize = sizeof(pd_decoder),
    .flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .slots = pd_decoder_slots,
};

/* module.attr as a new reference, or NULL with an exception set. */
static PyObject *pd_import_attr(const char *module, const char *attr)
{
    PyObject *mod = PyImport_ImportModule(module);
    PyObject *obj;

    if (mod == NULL) {
        return NULL;
    }
    obj = PyObject_GetAttrString(mod, attr);
    Py_DECREF(mod);
    return obj;
}

/* 1 when type.attr (an int) equals tuple's, 0 when not, -1 with an exception set. */
static int pd_same_as_tuple(PyObject *type, const char *attr)
{
    PyObject *mine = PyObject_GetAttrString(type, attr);
    PyObject *tuples = mine == NULL ? NULL : PyObject_GetAttrString((PyObject *)&PyTuple_Type, attr);
    int same = tuples == NULL ? -1 : PyObject_RichCompareBool(mine, tuples, Py_EQ);

    Py_XDECREF(mine);
    Py_XDECREF(tuples);
    return same;
}

/*
 * Packet and BadFrame must be NamedTuples with exactly these fields and no
 * storage besides the tuple's: pd_new_tuple builds them as tuple.__new__
 * would. Anything else fails the import, and framing.py falls back to the
 * Python decoder.
 */
static PyTypeObject *pd_tuple_class(const char *name, PyObject *fields)
{
    PyObject *cls;
    PyObject *got;
    PyTypeObject *type;
    int same;

    if (fields == NULL) {
        return NULL;
    }
    cls = pd_import_attr("protoduino.packets", name);
    if (cls == NULL) {
        Py_DECREF(fields);
        return NULL;
    }
    type = (PyTypeObject *)cls;
    same = PyType_Check(cls) && PyType_IsSubtype(type, &PyTuple_Type);
    for (size_t i = 0; same == 1 && i < 3; i++) {
        static const char *const layout[] = {"__basicsize__", "__itemsize__", "__dictoffset__"};
        same = pd_same_as_tuple(cls, layout[i]);
    }
    if (same == -1) {
        /* the exception of an attribute's lookup */
    } else if (same == 0) {
        PyErr_Format(PyExc_ImportError,
                     "protoduino.packets.%s is not a plain NamedTuple; "
                     "the C decoder cannot build it",
                     name);
        same = -1;
    } else {
        got = PyObject_GetAttrString(cls, "_fields");
        same = got == NULL ? -1 : PyObject_RichCompareBool(got, fields, Py_EQ);
        if (same == 0) {
            PyErr_Format(PyExc_ImportError, "protoduino.packets.%s has fields %R, expected %R",
                         name, got, fields);
        }
        Py_XDECREF(got);
    }
    Py_DECREF(fields);
    if (same != 1) {
        Py_DECREF(cls);
        return NULL;
    }
    return type;
}

/* The sizes this module was compiled with must be the Python package's. */
static int pd_check_constant(const char *name, long expected)
{
    PyObject *value = pd_import_attr("protoduino.constants", name);
    long got;

    if (value == NULL) {
        return -1;
    }
    got = PyLong_AsLong(value);
    Py_DECREF(value);
    if (got == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (got != expected) {
        PyErr_Format(PyExc_ImportError,
                     "protoduino.constants.%s is %ld but pd_protocol.h says %ld: rebuild", name,
                     got, expected);
        return -1;
    }
    return 0;
}

static int pd_load_packet_types(void)
{
    PyObject *enum_cls = pd_import_attr("protoduino.constants", "PacketType");
    PyObject *it;
    PyObject *member;

    if (enum_cls == NULL) {
        return -1;
    }
    it = PyObject_GetIter(enum_cls);
    Py_DECREF(enum_cls);
    if (it == NULL) {
        return -1;
    }
    while ((member = PyIter_Next(it)) != NULL) {
        long value = PyLong_AsLong(member);
        if (value == -1 && PyErr_Occurred()) {
            Py_DECREF(member);
            break;
        }
        if (value < 0 || value > 255) {
            PyErr_Format(PyExc_ImportError, "PacketType %R does not fit a TYPE byte", member);
            Py_DECREF(member);
            break;
        }
        Py_XDECREF(pd_packet_types[value]);
        pd_packet_types[value] = member; /* takes member's reference */
    }
    Py_DECREF(it);
    return PyErr_Occurred() ? -1 : 0;
}

static struct PyModuleDef pd_module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "protoduino._speedups",
    .m_doc = "C accelerator for protoduino.framing (optional; the pure-Python decoder is the "
             "reference).",
    .m_size = -1,
};

PyMODINIT_FUNC PyInit__speedups(void)
{
    static const uint8_t check[] = "123456789";
    PyObject *mod;

    pd_crc_table_init();
    if (pd_crc16_fast(check, 9) != 0x29B1u || pd_crc16(check, 9) != 0x29B1u) {
        PyErr_SetString(PyExc_ImportError, "CRC-16/CCITT-FALSE self-check failed");
        return NULL;
    }

    if (pd_check_constant("MAX_ENCODED_FRAME", PD_MAX_ENCODED_FRAME) < 0 ||
        pd_check_constant("HEADER_SIZE", PD_HEADER_SIZE) < 0 ||
        pd_check_constant("MIN_PACKET", PD_MIN_PACKET) < 0) {
        return NULL;
    }
    if (pd_packet_cls == NULL) {
        pd_packet_cls = pd_tuple_class("Packet", Py_BuildValue("(sss)", "type", "seq", "payload"));
        if (pd_packet_cls == NULL) {
            return NULL;
        }
    }
    if (pd_badframe_cls == NULL) {
        pd_badframe_cls = pd_tuple_class("BadFrame", Py_BuildValue("(ss)", "reason", "raw"));
        if (pd_badframe_cls == NULL) {
            return NULL;
        }
    }
    if (pd_counter_cls == NULL) {
        pd_counter_cls = pd_import_attr("collections", "Counter");
        if (pd_counter_cls == NULL) {
            return NULL;
        }
    }
    for (int i = 0; i < PD_R_COUNT; i++) {
        if (pd_reason_str[i] == NULL) {
            pd_reason_str[i] = PyUnicode_InternFromString(pd_reason_names[i]);
            if (pd_reason_str[i] == NULL) {
                return NULL;
            }
        }
    }
    pd_packet_alloc = (allocfunc)PyType_GetSlot(pd_packet_cls, Py_tp_alloc);
    pd_badframe_alloc = (allocfunc)PyType_GetSlot(pd_badframe_cls, Py_tp_alloc);
    if (pd_packet_alloc == NULL || pd_badframe_alloc == NULL) {
        PyErr_SetString(PyExc_ImportError, "Packet or BadFrame has no tp_alloc");
        return NULL;
    }
    if (pd_load_packet_types() < 0) {
        return NULL;
    }
    if (pd_decoder_type == NULL) {
        pd_decoder_type = PyType_FromSpec(&pd_decoder_spec);
        if (pd_decoder_type == NULL) {
            return NULL;
        }
    }
    mod = PyModule_Create(&pd_module);
    if (mod == NULL) {
        return NULL;
    }
    if (PyModule_AddObjectRef(mod, "StreamDecoder", pd_decoder_type) < 0 ||
        PyModule_AddStringConstant(mod, "SOURCE_DIGEST", PD_SPEEDUPS_DIGEST) < 0 ||
        PyModule_AddIntConstant(mod, "MAX_ENCODED_FRAME", PD_MAX_ENCODED_FRAME) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
