/* Hashes of chosen fields of records, for overseer.fleet.stamps (the exposition's stamps).
 *
 * field_hashes(records, fields) gives, as native 64-bit integers one after another, what
 * hash(tuple(record[f] for f in fields)) gives for each record, by CPython's own tuple hash (xxHash's
 * mixing of the items' hashes), without building the tuples: a changed robot's 50 components are
 * stamped at every scrape, and a tuple a component was most of that time.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#if SIZEOF_PY_UHASH_T > 4
#define PRIME_1 ((Py_uhash_t)11400714785074694791ULL)
#define PRIME_2 ((Py_uhash_t)14029467366897019727ULL)
#define PRIME_5 ((Py_uhash_t)2870177450012600261ULL)
#define ROTATE(x) (((x) << 31) | ((x) >> 33))
#else
#define PRIME_1 ((Py_uhash_t)2654435761UL)
#define PRIME_2 ((Py_uhash_t)2246822519UL)
#define PRIME_5 ((Py_uhash_t)374761393UL)
#define ROTATE(x) (((x) << 13) | ((x) >> 19))
#endif

/* records: a tuple of tuples (a tuple, so that hashing an item cannot take a record away), read as
 * tuples (a named tuple's fields, not an overridden __getitem__); fields: bytes, each the index of a
 * field, one at least. */
static PyObject *field_hashes(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2 || !PyTuple_Check(args[0]) || !PyBytes_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "field_hashes(records: tuple, fields: bytes)");
        return NULL;
    }
    PyObject *records = args[0];
    const unsigned char *fields = (const unsigned char *)PyBytes_AS_STRING(args[1]);
    Py_ssize_t field_count = PyBytes_GET_SIZE(args[1]);
    if (field_count == 0) {
        PyErr_SetString(PyExc_ValueError, "field_hashes: no fields");
        return NULL;
    }
    Py_ssize_t count = PyTuple_GET_SIZE(records);
    if (count > PY_SSIZE_T_MAX / (Py_ssize_t)sizeof(int64_t)) return PyErr_NoMemory();
    PyObject *out = PyBytes_FromStringAndSize(NULL, count * (Py_ssize_t)sizeof(int64_t));
    if (out == NULL) return NULL;
    char *hashes = PyBytes_AS_STRING(out);
    for (Py_ssize_t index = 0; index < count; index++) {
        PyObject *record = PyTuple_GET_ITEM(records, index);
        if (!PyTuple_Check(record)) {
            PyErr_Format(PyExc_TypeError, "field_hashes: record %zd is not a tuple", index);
            Py_DECREF(out);
            return NULL;
        }
        Py_uhash_t hash = PRIME_5;
        for (Py_ssize_t field = 0; field < field_count; field++) {
            if (fields[field] >= PyTuple_GET_SIZE(record)) {
                PyErr_Format(PyExc_IndexError, "field_hashes: record %zd has no field %d", index, fields[field]);
                Py_DECREF(out);
                return NULL;
            }
            Py_hash_t lane = PyObject_Hash(PyTuple_GET_ITEM(record, fields[field]));
            if (lane == -1) {
                Py_DECREF(out);
                return NULL;
            }
            hash += (Py_uhash_t)lane * PRIME_2;
            hash = ROTATE(hash);
            hash *= PRIME_1;
        }
        hash += (Py_uhash_t)field_count ^ (PRIME_5 ^ 3527539UL);
        if (hash == (Py_uhash_t)-1) hash = 1546275796;
        int64_t stamp = (int64_t)(Py_hash_t)hash;
        memcpy(hashes + index * (Py_ssize_t)sizeof stamp, &stamp, sizeof stamp); /* no alignment assumed */
    }
    return out;
}

static PyMethodDef methods[] = {
    {"field_hashes", (PyCFunction)(void (*)(void))field_hashes, METH_FASTCALL,
     "hash(tuple(record[f] for f in fields)) of each record, as native 64-bit integers."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    .m_base = PyModuleDef_HEAD_INIT,
    .m_name = "_cstamps",
    .m_doc = "Hashes of chosen fields of records, without a tuple a record.",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__cstamps(void) { return PyModule_Create(&module); }
