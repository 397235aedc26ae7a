/* The table of the fields of the core's structs, expanded from their lists (ln_model_fields.h, ln_data_fields.h):
 * what the Python binding builds its ctypes mirrors from, and what the native FMU's build writes the constant structs
 * with. */
#include <stddef.h>

#include "linknet.h"
#include "rigid.h"

typedef struct field {
    const char *name;
    int kind;           /* enum ln_field_kind */
    char code;          /* LN_FIELD_CODE of the type; 0 for OPAQUE */
    ln_int fixed;       /* FIXED: entries */
    size_t offset, size;
} field;

#define TABLE_ROW(name, kind, code, fixed, size) {#name, kind, code, fixed, offsetof(STRUCT, name), size},
#define TABLE_SCALAR(type, name) TABLE_ROW(name, LN_FIELD_SCALAR, LN_FIELD_CODE(type), 1, sizeof(type))
#define TABLE_ARRAY(type, name, count) TABLE_ROW(name, LN_FIELD_ARRAY, LN_FIELD_CODE(type), 0, sizeof(type))
#define TABLE_FIXED(type, name, n) TABLE_ROW(name, LN_FIELD_FIXED, LN_FIELD_CODE(type), n, sizeof(type))
#define TABLE_OPAQUE(type, name) TABLE_ROW(name, LN_FIELD_OPAQUE, 0, 0, sizeof(void *))
#define TABLE(LIST) LIST(TABLE_SCALAR, TABLE_ARRAY, TABLE_FIXED, TABLE_OPAQUE)

#define STRUCT ln_model
static const field model_fields[] = {TABLE(LN_MODEL_FIELDS)};
#undef STRUCT
#define STRUCT ln_method
static const field method_fields[] = {TABLE(LN_METHOD_FIELDS)};
#undef STRUCT
#define STRUCT struct ln_rigid_model
static const field rigid_fields[] = {TABLE(LN_RIGID_MODEL_FIELDS)};
#undef STRUCT
#define STRUCT ln_energy_terms
static const field energy_terms_fields[] = {TABLE(LN_ENERGY_TERMS_FIELDS)};
#undef STRUCT
/* ln_data's fields as the table's kinds: a field kept by reset is a scalar, an object owned or borrowed opaque */
#define TABLE_OWNED(type, name, release) TABLE_OPAQUE(type, name)
#define TABLE_BORROWED(type, name) TABLE_OPAQUE(type, name)
#define STRUCT ln_data
static const field data_fields[] = {
    LN_DATA_FIELDS(TABLE_SCALAR, TABLE_SCALAR, TABLE_ARRAY, TABLE_OWNED, TABLE_BORROWED)
};
#undef STRUCT

#define LENGTH(a) ((ln_int)(sizeof(a) / sizeof((a)[0])))

static const field *table(int which, ln_int *n)
{
    switch (which) {
    case LN_MODEL_STRUCT: *n = LENGTH(model_fields); return model_fields;
    case LN_METHOD_STRUCT: *n = LENGTH(method_fields); return method_fields;
    case LN_RIGID_MODEL_STRUCT: *n = LENGTH(rigid_fields); return rigid_fields;
    case LN_DATA_STRUCT: *n = LENGTH(data_fields); return data_fields;
    case LN_ENERGY_TERMS_STRUCT: *n = LENGTH(energy_terms_fields); return energy_terms_fields;
    default: *n = -1; return NULL;
    }
}

ln_int ln_struct_fields(int which)
{
    ln_int n;
    table(which, &n);
    return n;
}

size_t ln_struct_size(int which)
{
    switch (which) {
    case LN_MODEL_STRUCT: return sizeof(ln_model);
    case LN_METHOD_STRUCT: return sizeof(ln_method);
    case LN_RIGID_MODEL_STRUCT: return sizeof(struct ln_rigid_model);
    case LN_DATA_STRUCT: return sizeof(ln_data);
    case LN_ENERGY_TERMS_STRUCT: return sizeof(ln_energy_terms);
    default: return 0;
    }
}

const char *ln_struct_field(int which, ln_int i, int *kind, char *code, ln_int *fixed, size_t *offset, size_t *size)
{
    ln_int n;
    const field *f = table(which, &n);
    if (!f || i < 0 || i >= n) return NULL;
    f += i;
    if (kind) *kind = f->kind;
    if (code) *code = f->code;
    if (fixed) *fixed = f->fixed;
    if (offset) *offset = f->offset;
    if (size) *size = f->size;
    return f->name;
}

/* The entries of field i of a struct of the list: its count, read through s and m as the list writes it. */
#define COUNT_SCALAR(type, name) if (k++ == i) return 1;
#define COUNT_ARRAY(type, name, count) if (k++ == i) return s->name ? (ln_int)(count) : 0;
#define COUNT_FIXED(type, name, n) if (k++ == i) return n;
#define COUNT_OPAQUE(type, name) if (k++ == i) return 0;
#define COUNTS(LIST) LIST(COUNT_SCALAR, COUNT_ARRAY, COUNT_FIXED, COUNT_OPAQUE)
#define COUNT_OWNED(type, name, release) COUNT_OPAQUE(type, name)
#define COUNT_BORROWED(type, name) COUNT_OPAQUE(type, name)

static ln_int model_count(const ln_model *s, const ln_model *m, ln_int i)
{
    ln_int k = 0;
    (void)m;
    COUNTS(LN_MODEL_FIELDS)
    return -1;
}

static ln_int method_count(const ln_method *s, const ln_model *m, ln_int i)
{
    ln_int k = 0;
    (void)m;
    COUNTS(LN_METHOD_FIELDS)
    return -1;
}

static ln_int rigid_count(const struct ln_rigid_model *s, const ln_model *m, ln_int i)
{
    ln_int k = 0;
    COUNTS(LN_RIGID_MODEL_FIELDS)
    return -1;
}

static ln_int energy_terms_count(const ln_energy_terms *s, const ln_model *m, ln_int i)
{
    ln_int k = 0;
    COUNTS(LN_ENERGY_TERMS_FIELDS)
    return -1;
}

static ln_int data_count(const ln_data *s, const ln_model *m, ln_int i)
{
    ln_int k = 0;
    LN_DATA_FIELDS(COUNT_SCALAR, COUNT_SCALAR, COUNT_ARRAY, COUNT_OWNED, COUNT_BORROWED)
    return -1;
}

ln_int ln_struct_field_count(int which, ln_int i, const void *s, const ln_model *m)
{
    switch (which) {
    case LN_MODEL_STRUCT: return model_count(s, s, i);
    case LN_METHOD_STRUCT: return method_count(s, m, i);
    case LN_RIGID_MODEL_STRUCT: return m ? rigid_count(s, m, i) : -1;
    case LN_DATA_STRUCT: return m ? data_count(s, m, i) : -1;
    case LN_ENERGY_TERMS_STRUCT: return m ? energy_terms_count(s, m, i) : -1;
    default: return -1;
    }
}
