/* Compiled status decoding for the CDR and ROS 1 codecs (overseer.codec.compiled is its Python face).
 *
 * It decodes exactly as the pure-Python readers in cdr.py and ros1.py do, into the same
 * DiagnosticStatus named tuples, with the same DecodeError messages. Every length read from the payload
 * is checked against the bytes that remain before it is used or anything is allocated for it: a hostile
 * payload costs at most its own size (and what the shared tables below keep of it, bounded by them) and
 * ends in DecodeError. A length or count read from the payload is
 * compared, as an unsigned 64-bit number, with the bytes that remain, so nothing can overflow or turn
 * negative, whatever the width of Py_ssize_t.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

/* The three layouts: CDR aligns lengths to 4 bytes and ends strings with NUL; ROS 1 does neither. */
enum layout { CDR_LE = 0, CDR_BE = 1, ROS1 = 2 };

/* Smallest encoding of one key-value pair (two empty strings), to bound a value count. */
#define MIN_KEY_VALUE_BYTES 8

static PyTypeObject *status_type = NULL; /* overseer.messages.DiagnosticStatus */
static PyObject *decode_error = NULL;    /* overseer.codec.errors.DecodeError */

/* The key-value pairs and the values tuples decoded before, each kept once: robots of one fleet report
 * the same values (a camera's 30.0 fps, a motor's "Running") and keep them for hours, and a pair with
 * its text costs more than the component that holds it. Only small items are kept: a pair whose key and
 * value hold SHARED_TEXT bytes or fewer, a values tuple of at most SHARED_PAIRS such pairs. A table that
 * reaches its limit starts again empty, so that a fleet of ever-new values keeps at most that many items
 * it no longer uses: about 12 MB in all, with every text as long as may be kept.
 *
 * Looking up a value no one else reported costs about as much as decoding it, and some values are
 * measurements that never repeat. So each pair's key (each values tuple's status name) has a record: a
 * record whose last SHARED_WINDOW lookups found an equal fewer than one time in SHARED_WORTH rests
 * (shares nothing) for the next SHARED_REST items, then tries again. Records are slots picked by the
 * address of the key or name, which the decoder interns; keys or names that share a slot share its
 * record and its rest, which costs at most some sharing, never a wrong value. */
#define SHARED_PAIRS_LIMIT 16384
#define SHARED_VALUES_LIMIT 2048
#define SHARED_TEXT 64
#define SHARED_PAIRS 8
#define SHARED_WINDOW 64
#define SHARED_WORTH 4
#define SHARED_REST (16 * SHARED_WINDOW)
#define SHARED_SLOTS 1024

struct sharing {
    uint16_t lookups, found; /* in this window */
    uint16_t resting;        /* items left to pass unshared */
};

struct shared_table {
    PyObject *kept; /* a dict of each item kept to itself */
    Py_ssize_t limit;
    struct sharing slots[SHARED_SLOTS];
};

static struct shared_table shared_pairs = {.limit = SHARED_PAIRS_LIMIT};   /* slots by key */
static struct shared_table shared_values = {.limit = SHARED_VALUES_LIMIT}; /* slots by status name */

struct reader {
    const unsigned char *data;
    Py_ssize_t end; /* reading stops here (never past the buffer) */
    enum layout layout;
    /* The largest of what the statuses read so far hold, for the fleet model's limits. */
    Py_ssize_t longest_text; /* in bytes, which no text's length in characters exceeds */
    uint32_t most_values;
    unsigned char highest_level;
};

static uint32_t u32_at(const struct reader *r, Py_ssize_t at) {
    const unsigned char *p = r->data + at;
    if (r->layout == CDR_BE) {
        return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
    }
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static Py_ssize_t aligned(const struct reader *r, Py_ssize_t at) {
    return r->layout == ROS1 ? at : (at + 3) & ~(Py_ssize_t)3;
}

/* The string at *at (aligned first); moves *at past it. NULL with DecodeError set when malformed. */
static PyObject *read_string(struct reader *r, Py_ssize_t *at) {
    Py_ssize_t pos = aligned(r, *at);
    if (pos + 4 > r->end) {
        PyErr_SetString(decode_error, "payload ends before a string length");
        return NULL;
    }
    uint32_t length = u32_at(r, pos);
    pos += 4;
    if ((uint64_t)length > (uint64_t)(r->end - pos)) {
        PyErr_Format(decode_error, "string length %lu runs past the payload", (unsigned long)length);
        return NULL;
    }
    Py_ssize_t text_length = (Py_ssize_t)length;
    if (r->layout != ROS1 && length > 0) {
        if (r->data[pos + text_length - 1] != 0) {
            PyErr_SetString(decode_error, "string is not NUL-terminated");
            return NULL;
        }
        text_length -= 1;
    }
    *at = pos + (Py_ssize_t)length;
    if (text_length > r->longest_text) {
        r->longest_text = text_length;
    }
    return PyUnicode_DecodeUTF8((const char *)r->data + pos, text_length, "replace");
}

/* A new DiagnosticStatus; steals the references to its five fields. */
static PyObject *new_status(PyObject *fields[5]) {
    PyObject *status = status_type->tp_alloc(status_type, 5);
    if (status == NULL) {
        for (int i = 0; i < 5; i++) {
            Py_DECREF(fields[i]);
        }
        return NULL;
    }
    for (int i = 0; i < 5; i++) {
        PyTuple_SET_ITEM(status, i, fields[i]);
    }
    return status;
}

/* The bytes of a text's characters, as it holds them. */
static Py_ssize_t text_bytes(PyObject *text) {
    return PyUnicode_GET_LENGTH(text) * PyUnicode_KIND(text);
}

/* `item`, or an equal one the table kept before (a new reference either way); steals `item`.
 * `by` (the key or name, interned) picks the record of how often sharing found an equal. */
static PyObject *shared(struct shared_table *table, PyObject *by, PyObject *item) {
    uintptr_t address = (uintptr_t)by;
    struct sharing *record = &table->slots[((address >> 4) ^ (address >> 14)) & (SHARED_SLOTS - 1)];
    if (record->resting > 0) {
        record->resting--;
        return item;
    }
    if (PyDict_GET_SIZE(table->kept) >= table->limit) {
        PyDict_Clear(table->kept);
    }
    PyObject *kept = PyDict_SetDefault(table->kept, item, item);
    if (kept == NULL) {
        Py_DECREF(item);
        return NULL;
    }
    record->found += kept != item;
    Py_INCREF(kept);
    Py_DECREF(item);
    if (++record->lookups == SHARED_WINDOW) {
        if (record->found * SHARED_WORTH < SHARED_WINDOW) {
            record->resting = SHARED_REST;
        }
        record->lookups = record->found = 0;
    }
    return kept;
}

/* The status at *at; moves *at past it. NULL with an exception set when malformed. */
static PyObject *read_status(struct reader *r, Py_ssize_t *at) {
    Py_ssize_t pos = *at;
    if (pos >= r->end) {
        PyErr_SetString(decode_error, "payload ends inside a status");
        return NULL;
    }
    PyObject *fields[5] = {NULL, NULL, NULL, NULL, NULL};
    unsigned char level = r->data[pos];
    if (level > r->highest_level) {
        r->highest_level = level;
    }
    fields[0] = PyLong_FromLong((long)level);
    if (fields[0] == NULL) {
        return NULL;
    }
    pos += 1;
    for (int i = 1; i < 4; i++) {
        fields[i] = read_string(r, &pos);
        if (fields[i] == NULL) {
            goto fail;
        }
        /* Robots of one fleet repeat the same names, messages and hardware_ids: the model keeps one. */
        PyUnicode_InternInPlace(&fields[i]);
    }
    pos = aligned(r, pos);
    if (pos + 4 > r->end) {
        PyErr_SetString(decode_error, r->layout == ROS1 ? "payload ends before a value count"
                                                         : "payload ends before a values sequence");
        goto fail;
    }
    uint32_t count = u32_at(r, pos);
    pos += 4;
    if ((uint64_t)count * MIN_KEY_VALUE_BYTES > (uint64_t)(r->end - pos)) {
        PyErr_Format(decode_error, "value count %lu runs past the payload", (unsigned long)count);
        goto fail;
    }
    if (count > r->most_values) {
        r->most_values = count;
    }
    fields[4] = PyTuple_New((Py_ssize_t)count);
    if (fields[4] == NULL) {
        goto fail;
    }
    int small = count <= SHARED_PAIRS; /* so far: the values tuple may be shared */
    for (uint32_t i = 0; i < count; i++) {
        PyObject *key = read_string(r, &pos);
        if (key == NULL) {
            goto fail;
        }
        PyUnicode_InternInPlace(&key); /* keys repeat too; values are shared below, as pairs */
        PyObject *value = read_string(r, &pos);
        if (value == NULL) {
            Py_DECREF(key);
            goto fail;
        }
        PyObject *pair = PyTuple_New(2);
        if (pair == NULL) {
            Py_DECREF(key);
            Py_DECREF(value);
            goto fail;
        }
        PyTuple_SET_ITEM(pair, 0, key);
        PyTuple_SET_ITEM(pair, 1, value);
        if (text_bytes(key) + text_bytes(value) <= SHARED_TEXT) {
            pair = shared(&shared_pairs, key, pair);
            if (pair == NULL) {
                goto fail;
            }
        } else {
            small = 0;
        }
        PyTuple_SET_ITEM(fields[4], i, pair);
    }
    if (count > 0 && small) {
        fields[4] = shared(&shared_values, fields[1], fields[4]);
        if (fields[4] == NULL) {
            goto fail;
        }
    }
    *at = pos;
    return new_status(fields);
fail:
    for (int i = 0; i < 5; i++) {
        Py_XDECREF(fields[i]);
    }
    return NULL;
}

/* Python's hash of bytes(data[0:length]), as the ingest's pure-Python path computes it. */
static Py_hash_t hash_bytes(const unsigned char *data, Py_ssize_t length) {
#if PY_VERSION_HEX >= 0x030E0000
    return Py_HashBuffer(data, length);
#else
    return _Py_HashBytes(data, length);
#endif
}

static int check_ready(void) {
    if (status_type == NULL || decode_error == NULL || shared_pairs.kept == NULL ||
        shared_values.kept == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "overseer.codec._cstatus.setup() was not called");
        return -1;
    }
    return 0;
}

static int parse_layout(PyObject *arg, enum layout *layout) {
    long value = PyLong_AsLong(arg);
    if (value == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (value != CDR_LE && value != CDR_BE && value != ROS1) {
        PyErr_Format(PyExc_ValueError, "unknown layout %ld", value);
        return -1;
    }
    *layout = (enum layout)value;
    return 0;
}

/* Checks a caller's position and end against the buffer: these are programming errors, not bad input. */
static int check_span(const Py_buffer *view, Py_ssize_t pos, Py_ssize_t end) {
    if (pos < 0 || end < 0 || end > view->len) {
        PyErr_Format(PyExc_ValueError, "position %zd or end %zd outside a payload of %zd bytes", pos, end,
                     view->len);
        return -1;
    }
    return 0;
}

/* Positions go to an array('I'): a payload must not be longer than 4 GiB. */
static int check_positions_fit(Py_ssize_t end) {
    if ((uint64_t)end > (uint64_t)UINT32_MAX) {
        PyErr_SetString(PyExc_OverflowError, "payload longer than 4 GiB");
        return -1;
    }
    return 0;
}

/* Exports a writable one-dimensional buffer of `itemsize`-byte items in format `format` ("I", "q"). */
static int writable_items(PyObject *obj, Py_buffer *view, Py_ssize_t itemsize, const char *format,
                          const char *what) {
    if (PyObject_GetBuffer(obj, view, PyBUF_WRITABLE | PyBUF_FORMAT | PyBUF_ND) < 0) {
        return -1;
    }
    if (view->itemsize != itemsize || view->ndim != 1 || view->format == NULL ||
        strcmp(view->format, format) != 0) {
        PyErr_Format(PyExc_TypeError, "%s must be an array('%s')", what, format);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static PyObject *status_and_position(PyObject *status, Py_ssize_t pos) {
    if (status == NULL) {
        return NULL;
    }
    PyObject *position = PyLong_FromSsize_t(pos);
    if (position == NULL) {
        Py_DECREF(status);
        return NULL;
    }
    PyObject *pair = PyTuple_New(2);
    if (pair == NULL) {
        Py_DECREF(status);
        Py_DECREF(position);
        return NULL;
    }
    PyTuple_SET_ITEM(pair, 0, status);
    PyTuple_SET_ITEM(pair, 1, position);
    return pair;
}

/* read_status_*(payload, pos, end) -> (DiagnosticStatus, position after it): a codec's StatusReader. */
static PyObject *read_status_in(enum layout layout, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_Format(PyExc_TypeError, "expected payload, pos, end; got %zd arguments", nargs);
        return NULL;
    }
    if (check_ready() < 0) {
        return NULL;
    }
    Py_ssize_t pos = PyLong_AsSsize_t(args[1]);
    if (pos == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t end = PyLong_AsSsize_t(args[2]);
    if (end == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_buffer view;
    if (PyObject_GetBuffer(args[0], &view, PyBUF_SIMPLE) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    if (check_span(&view, pos, end) == 0) {
        struct reader r = {(const unsigned char *)view.buf, end, layout, 0, 0, 0};
        PyObject *status = read_status(&r, &pos);
        result = status_and_position(status, pos);
    }
    PyBuffer_Release(&view);
    return result;
}

static PyObject *read_status_cdr_le(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    return read_status_in(CDR_LE, args, nargs);
}

static PyObject *read_status_cdr_be(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    return read_status_in(CDR_BE, args, nargs);
}

static PyObject *read_status_ros1(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    return read_status_in(ROS1, args, nargs);
}

/* read_statuses(layout, payload, pos, end, bounds) -> tuple of statuses.
 *
 * Reads len(bounds) - 1 statuses from pos; bounds (an array('I')) receives where each began and where
 * the last one ended.
 */
static PyObject *read_statuses(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_Format(PyExc_TypeError, "expected layout, payload, pos, end, bounds; got %zd arguments", nargs);
        return NULL;
    }
    enum layout layout;
    if (check_ready() < 0 || parse_layout(args[0], &layout) < 0) {
        return NULL;
    }
    Py_ssize_t pos = PyLong_AsSsize_t(args[2]);
    if (pos == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t end = PyLong_AsSsize_t(args[3]);
    if (end == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_buffer view, bounds_view;
    if (PyObject_GetBuffer(args[1], &view, PyBUF_SIMPLE) < 0) {
        return NULL;
    }
    if (writable_items(args[4], &bounds_view, 4, "I", "bounds") < 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    PyObject *statuses = NULL;
    Py_ssize_t count = bounds_view.len / 4 - 1;
    if (count < 0) {
        PyErr_SetString(PyExc_ValueError, "bounds must hold at least one position");
        goto done;
    }
    if (check_span(&view, pos, end) < 0 || check_positions_fit(end) < 0) {
        goto done;
    }
    statuses = PyTuple_New(count);
    if (statuses == NULL) {
        goto done;
    }
    struct reader r = {(const unsigned char *)view.buf, end, layout, 0, 0, 0};
    uint32_t *bounds = (uint32_t *)bounds_view.buf;
    bounds[0] = (uint32_t)pos;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *status = read_status(&r, &pos);
        if (status == NULL) {
            Py_CLEAR(statuses);
            goto done;
        }
        PyTuple_SET_ITEM(statuses, i, status);
        bounds[i + 1] = (uint32_t)pos;
    }
done:
    PyBuffer_Release(&bounds_view);
    PyBuffer_Release(&view);
    return statuses;
}

/* scan_changed(layout, payload, pos, end, bounds, hashes, misaligned, max_length, max_values)
 *     -> ([(index, status)], pos, fits).
 *
 * The ingest's comparison of a payload with the last one, status by status (see PayloadIngest):
 * a status whose bytes hash as before, at an offset that keeps the alignment (shift & misaligned == 0),
 * is skipped; any other is decoded, and its bound and hash updated in place. `fits` is true when every
 * status decoded has a level of 0 to 3, no text of more than max_length bytes (so of no more characters)
 * and no more than max_values key-values: the fleet model's limits cut nothing of them.
 */
static PyObject *scan_changed(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 9) {
        PyErr_Format(PyExc_TypeError,
                     "expected layout, payload, pos, end, bounds, hashes, misaligned, max_length, max_values;"
                     " got %zd arguments",
                     nargs);
        return NULL;
    }
    enum layout layout;
    if (check_ready() < 0 || parse_layout(args[0], &layout) < 0) {
        return NULL;
    }
    Py_ssize_t pos = PyLong_AsSsize_t(args[2]);
    if (pos == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t end = PyLong_AsSsize_t(args[3]);
    if (end == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t misaligned = PyLong_AsSsize_t(args[6]);
    if (misaligned == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t max_length = PyLong_AsSsize_t(args[7]);
    if (max_length == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_ssize_t max_values = PyLong_AsSsize_t(args[8]);
    if (max_values == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Py_buffer view, bounds_view, hashes_view;
    if (PyObject_GetBuffer(args[1], &view, PyBUF_SIMPLE) < 0) {
        return NULL;
    }
    if (writable_items(args[4], &bounds_view, 4, "I", "bounds") < 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    if (writable_items(args[5], &hashes_view, 8, "q", "hashes") < 0) {
        PyBuffer_Release(&bounds_view);
        PyBuffer_Release(&view);
        return NULL;
    }
    PyObject *changed = NULL, *result = NULL;
    Py_ssize_t count = hashes_view.len / 8;
    if (bounds_view.len / 4 != count + 1) {
        PyErr_SetString(PyExc_ValueError, "bounds must hold one more position than hashes");
        goto done;
    }
    if (check_span(&view, pos, end) < 0 || check_positions_fit(end) < 0) {
        goto done;
    }
    changed = PyList_New(0);
    if (changed == NULL) {
        goto done;
    }
    struct reader r = {(const unsigned char *)view.buf, end, layout, 0, 0, 0};
    uint32_t *bounds = (uint32_t *)bounds_view.buf;
    int64_t *hashes = (int64_t *)hashes_view.buf;
    Py_ssize_t shift = 0; /* how much later than in the last payload the statuses now sit */
    for (Py_ssize_t index = 0; index < count; index++) {
        Py_ssize_t after = (Py_ssize_t)bounds[index + 1] + shift;
        int same = (shift & misaligned) == 0 && after > pos && after <= end &&
                   hash_bytes(r.data + pos, after - pos) == (Py_hash_t)hashes[index];
        if (!same) {
            after = pos;
            PyObject *status = read_status(&r, &after);
            if (status == NULL) {
                goto done;
            }
            PyObject *entry = PyTuple_New(2), *position = PyLong_FromSsize_t(index);
            if (entry == NULL || position == NULL) {
                Py_XDECREF(entry);
                Py_XDECREF(position);
                Py_DECREF(status);
                goto done;
            }
            PyTuple_SET_ITEM(entry, 0, position);
            PyTuple_SET_ITEM(entry, 1, status);
            int failed = PyList_Append(changed, entry);
            Py_DECREF(entry);
            if (failed < 0) {
                goto done;
            }
            hashes[index] = (int64_t)hash_bytes(r.data + pos, after - pos);
            shift = after - (Py_ssize_t)bounds[index + 1];
            bounds[index + 1] = (uint32_t)after;
        } else if (shift != 0) {
            bounds[index + 1] = (uint32_t)after;
        }
        pos = after;
    }
    int fits = r.highest_level <= 3 && r.longest_text <= max_length && (Py_ssize_t)r.most_values <= max_values;
    result = Py_BuildValue("(OnO)", changed, pos, fits ? Py_True : Py_False);
done:
    Py_XDECREF(changed);
    PyBuffer_Release(&hashes_view);
    PyBuffer_Release(&bounds_view);
    PyBuffer_Release(&view);
    return result;
}

/* setup(status_type, decode_error): the named tuple to build and the exception to raise. */
static PyObject *setup(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_Format(PyExc_TypeError, "expected status_type, decode_error; got %zd arguments", nargs);
        return NULL;
    }
    PyObject *type = args[0], *error = args[1];
    /* A named tuple adds no fields to tuple (__slots__ = ()), so it is allocated and filled like one. */
    if (!PyType_Check(type) || !PyType_IsSubtype((PyTypeObject *)type, &PyTuple_Type) ||
        ((PyTypeObject *)type)->tp_basicsize != PyTuple_Type.tp_basicsize ||
        ((PyTypeObject *)type)->tp_itemsize != PyTuple_Type.tp_itemsize) {
        PyErr_SetString(PyExc_TypeError, "status_type must be a named tuple class");
        return NULL;
    }
    if (!PyType_Check(error) || !PyType_IsSubtype((PyTypeObject *)error, (PyTypeObject *)PyExc_Exception)) {
        PyErr_SetString(PyExc_TypeError, "decode_error must be an exception class");
        return NULL;
    }
    if (shared_pairs.kept == NULL && (shared_pairs.kept = PyDict_New()) == NULL) {
        return NULL;
    }
    if (shared_values.kept == NULL && (shared_values.kept = PyDict_New()) == NULL) {
        return NULL;
    }
    Py_INCREF(type);
    Py_INCREF(error);
    Py_XSETREF(status_type, (PyTypeObject *)type);
    Py_XSETREF(decode_error, error);
    Py_RETURN_NONE;
}

/* shared_reset(): forget every item kept and every record, as at import. */
static PyObject *shared_reset(PyObject *module, PyObject *unused) {
    if (check_ready() < 0) {
        return NULL;
    }
    struct shared_table *tables[] = {&shared_pairs, &shared_values};
    for (int i = 0; i < 2; i++) {
        PyDict_Clear(tables[i]->kept);
        memset(tables[i]->slots, 0, sizeof tables[i]->slots);
    }
    Py_RETURN_NONE;
}

/* shared_sizes(): how many key-value pairs and values tuples the decoder keeps to share. */
static PyObject *shared_sizes(PyObject *module, PyObject *unused) {
    if (check_ready() < 0) {
        return NULL;
    }
    return Py_BuildValue("(nn)", PyDict_GET_SIZE(shared_pairs.kept), PyDict_GET_SIZE(shared_values.kept));
}

static PyMethodDef methods[] = {
    {"setup", (PyCFunction)(void (*)(void))setup, METH_FASTCALL,
     "setup(status_type, decode_error): what to build and what to raise."},
    {"read_status_cdr_le", (PyCFunction)(void (*)(void))read_status_cdr_le, METH_FASTCALL,
     "The little-endian CDR status at pos, and the position after it."},
    {"read_status_cdr_be", (PyCFunction)(void (*)(void))read_status_cdr_be, METH_FASTCALL,
     "The big-endian CDR status at pos, and the position after it."},
    {"read_status_ros1", (PyCFunction)(void (*)(void))read_status_ros1, METH_FASTCALL,
     "The ROS 1 status at pos, and the position after it."},
    {"read_statuses", (PyCFunction)(void (*)(void))read_statuses, METH_FASTCALL,
     "len(bounds) - 1 statuses from pos, filling bounds with where each began and the last ended."},
    {"scan_changed", (PyCFunction)(void (*)(void))scan_changed, METH_FASTCALL,
     "The statuses that changed since the last payload, updating bounds and hashes in place."},
    {"shared_reset", shared_reset, METH_NOARGS, "Forget every key-value pair and values tuple kept, and why."},
    {"shared_sizes", shared_sizes, METH_NOARGS,
     "How many key-value pairs and values tuples the decoder keeps to share."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    .m_base = PyModuleDef_HEAD_INIT,
    .m_name = "_cstatus",
    .m_doc = "Compiled status decoding for overseer.codec.",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__cstatus(void) {
    PyObject *module = PyModule_Create(&module_def);
    if (module == NULL) {
        return NULL;
    }
    if (PyModule_AddIntConstant(module, "CDR_LE", CDR_LE) < 0 ||
        PyModule_AddIntConstant(module, "CDR_BE", CDR_BE) < 0 ||
        PyModule_AddIntConstant(module, "ROS1", ROS1) < 0 ||
        PyModule_AddIntConstant(module, "SHARED_PAIRS_LIMIT", SHARED_PAIRS_LIMIT) < 0 ||
        PyModule_AddIntConstant(module, "SHARED_VALUES_LIMIT", SHARED_VALUES_LIMIT) < 0 ||
        PyModule_AddIntConstant(module, "SHARED_TEXT", SHARED_TEXT) < 0 ||
        PyModule_AddIntConstant(module, "SHARED_PAIRS", SHARED_PAIRS) < 0) {
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
