/* Deflate, inflate and CRC-32 combining for overseer.fleet.deflated, without letting go of the
 * interpreter lock.
 *
 * Python's zlib module lets go of the lock around every call. A scrape makes tens of thousands of small
 * calls (a few per robot), and beside a thread that keeps the interpreter busy (the ingest) each one then
 * waits up to the switch interval to take the lock back: seconds a scrape. A few kilobytes take
 * microseconds to compress, far less than that wait, so these functions keep the lock.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>
#include <zlib.h>

/* One compressor and one decompressor, reset for each piece rather than set up and torn down: a
 * compressor's state is about 48 kB, and allocating it for each of a scrape's pieces, between the small
 * pieces kept, left the heap full of holes. Sharing them is safe because the interpreter lock is held
 * throughout every call. Compressed output goes to a scratch buffer first, so that each piece is
 * allocated once at its size. */
static z_stream deflater, inflater;
static int deflater_ready = 0, inflater_ready = 0;
static int deflater_settings[3]; /* level, window bits, memory level, while deflater_ready */
static Bytef *scratch = NULL;
static size_t scratch_size = 0;
#define SCRATCH_LIMIT (1 << 20) /* larger pieces (rare: a family of the whole fleet) get a buffer of their own */

static int deflater_for(int level, int window_bits, int memory_level) {
    int wanted[3] = {level, window_bits, memory_level};
    if (deflater_ready && memcmp(wanted, deflater_settings, sizeof wanted) == 0) {
        if (deflateReset(&deflater) == Z_OK) return 0;
        PyErr_SetString(PyExc_RuntimeError, "deflate: zlib could not start again");
        return -1;
    }
    if (deflater_ready) deflateEnd(&deflater);
    deflater_ready = 0;
    memset(&deflater, 0, sizeof deflater);
    if (deflateInit2(&deflater, level, Z_DEFLATED, -window_bits, memory_level, Z_DEFAULT_STRATEGY) != Z_OK) {
        PyErr_SetString(PyExc_ValueError, "deflate: zlib refused the settings");
        return -1;
    }
    memcpy(deflater_settings, wanted, sizeof wanted);
    deflater_ready = 1;
    return 0;
}

static Bytef *output_room(size_t size, Bytef **own) {
    *own = NULL;
    if (size > SCRATCH_LIMIT) {
        *own = PyMem_RawMalloc(size);
        if (*own == NULL) PyErr_NoMemory();
        return *own;
    }
    if (size > scratch_size) {
        Bytef *grown = PyMem_RawRealloc(scratch, size);
        if (grown == NULL) {
            PyErr_NoMemory();
            return NULL;
        }
        scratch = grown;
        scratch_size = size;
    }
    return scratch;
}

/* `value` as an int from `low` to `high` into `*out`; -1 with ValueError or TypeError otherwise. */
static int small_int(PyObject *value, long low, long high, int *out) {
    long number = PyLong_AsLong(value);
    if (number == -1 && PyErr_Occurred()) return -1;
    if (number < low || number > high) {
        PyErr_Format(PyExc_ValueError, "deflate: a setting from %ld to %ld, got %ld", low, high, number);
        return -1;
    }
    *out = (int)number;
    return 0;
}

/* deflate(text, level, window_bits, memory_level) -> (raw deflate ending in a sync flush, CRC-32) */
static PyObject *deflate_piece(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "deflate(text, level, window_bits, memory_level)");
        return NULL;
    }
    int level, window_bits, memory_level;
    if (small_int(args[1], -1, 9, &level) < 0 || small_int(args[2], 9, 15, &window_bits) < 0 ||
        small_int(args[3], 1, 9, &memory_level) < 0)
        return NULL;
    Py_buffer text;
    if (PyObject_GetBuffer(args[0], &text, PyBUF_SIMPLE) < 0) return NULL;
    PyObject *result = NULL;
    Bytef *own = NULL;
    if ((unsigned long long)text.len > UINT_MAX / 2) {
        PyErr_SetString(PyExc_OverflowError, "deflate: a piece of at most 2 GB");
        goto done;
    }
    if (deflater_for(level, window_bits, memory_level) < 0) goto done;
    /* deflateBound covers a finished stream; the sync flush's empty stored block needs a few more. */
    size_t bound = deflateBound(&deflater, (uLong)text.len) + 16;
    Bytef *room = output_room(bound, &own);
    if (room == NULL) goto done;
    deflater.next_in = (Bytef *)text.buf;
    deflater.avail_in = (uInt)text.len;
    deflater.next_out = room;
    deflater.avail_out = (uInt)bound;
    if (deflate(&deflater, Z_SYNC_FLUSH) != Z_OK || deflater.avail_in != 0 || deflater.avail_out == 0) {
        PyErr_SetString(PyExc_RuntimeError, "deflate: zlib did not take the whole piece");
        goto done;
    }
    uLong crc = crc32(0L, (const Bytef *)text.buf, (uInt)text.len);
    PyObject *data = PyBytes_FromStringAndSize((const char *)room, (Py_ssize_t)(bound - deflater.avail_out));
    if (data != NULL) result = Py_BuildValue("(Nk)", data, crc);
done:
    PyMem_RawFree(own);
    PyBuffer_Release(&text);
    return result;
}

static int ends_in_sync_marker(const Bytef *data, Py_ssize_t size) {
    static const Bytef marker[4] = {0x00, 0x00, 0xff, 0xff};
    return size >= 4 && memcmp(data + size - 4, marker, 4) == 0;
}

/* inflate(data, size) -> the `size` bytes of text that raw deflate `data` holds */
static PyObject *inflate_piece(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "inflate(data, size)");
        return NULL;
    }
    Py_ssize_t size = PyLong_AsSsize_t(args[1]);
    if (size == -1 && PyErr_Occurred()) return NULL;
    if (size < 0 || (unsigned long long)size > UINT_MAX / 2) {
        PyErr_SetString(PyExc_ValueError, "inflate: a size from 0 to 2 GB");
        return NULL;
    }
    Py_buffer data;
    if (PyObject_GetBuffer(args[0], &data, PyBUF_SIMPLE) < 0) return NULL;
    PyObject *out = NULL;
    if ((unsigned long long)data.len > UINT_MAX / 2) {
        PyErr_SetString(PyExc_OverflowError, "inflate: a piece of at most 2 GB");
        goto done;
    }
    int started = inflater_ready ? inflateReset(&inflater) : inflateInit2(&inflater, -MAX_WBITS);
    if (started != Z_OK) {
        inflater_ready = 0;
        memset(&inflater, 0, sizeof inflater);
        PyErr_SetString(PyExc_RuntimeError, "inflate: zlib could not start");
        goto done;
    }
    inflater_ready = 1;
    out = PyBytes_FromStringAndSize(NULL, size);
    if (out == NULL) goto done;
    inflater.next_in = (Bytef *)data.buf;
    inflater.avail_in = (uInt)data.len;
    inflater.next_out = (Bytef *)PyBytes_AS_STRING(out);
    inflater.avail_out = (uInt)size;
    int status = inflate(&inflater, Z_SYNC_FLUSH);
    /* Whole, and joinable: no final block, and ending in a sync flush's empty stored block. */
    int complete = (status == Z_OK || status == Z_BUF_ERROR) && inflater.avail_out == 0 &&
                   inflater.avail_in == 0 && ends_in_sync_marker((const Bytef *)data.buf, data.len);
    if (!complete) {
        Py_CLEAR(out);
        PyErr_Format(PyExc_ValueError, "inflate: the data does not hold the %zd bytes of text it should", size);
    }
done:
    PyBuffer_Release(&data);
    return out;
}

/* crc32_combine(crc1, crc2, size2) -> the CRC-32 of A+B from A's, B's and B's length */
static PyObject *combine(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "crc32_combine(crc1, crc2, size2)");
        return NULL;
    }
    unsigned long crc1 = PyLong_AsUnsignedLong(args[0]);
    if (crc1 == (unsigned long)-1 && PyErr_Occurred()) return NULL;
    unsigned long crc2 = PyLong_AsUnsignedLong(args[1]);
    if (crc2 == (unsigned long)-1 && PyErr_Occurred()) return NULL;
    long long size2 = PyLong_AsLongLong(args[2]);
    if (size2 == -1 && PyErr_Occurred()) return NULL;
    if (crc1 > 0xFFFFFFFFUL || crc2 > 0xFFFFFFFFUL || size2 < 0) {
        PyErr_SetString(PyExc_ValueError, "crc32_combine: CRC-32s of 32 bits and a size of 0 or more");
        return NULL;
    }
    return PyLong_FromUnsignedLong(crc32_combine(crc1, crc2, (z_off_t)size2));
}

static PyMethodDef methods[] = {
    {"deflate", (PyCFunction)(void (*)(void))deflate_piece, METH_FASTCALL,
     "deflate(text, level, window_bits, memory_level) -> (raw deflate ending in a sync flush, CRC-32)"},
    {"inflate", (PyCFunction)(void (*)(void))inflate_piece, METH_FASTCALL,
     "inflate(data, size) -> the size bytes of text raw deflate data holds"},
    {"crc32_combine", (PyCFunction)(void (*)(void))combine, METH_FASTCALL,
     "crc32_combine(crc1, crc2, size2) -> the CRC-32 of A+B"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    .m_base = PyModuleDef_HEAD_INIT,
    .m_name = "_cdeflate",
    .m_doc = "Deflate pieces without letting go of the interpreter lock.",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__cdeflate(void) { return PyModule_Create(&module); }
