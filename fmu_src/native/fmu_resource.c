/* The native FMU's resource file, read and checked (fmu_resource.h). */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_resource.h"

#define HEADER_SIZE 48
#define ENTRY_SIZE 64
#define BYTE_ORDER_MARK 0x01020304u
static const char magic[8] = {'L', 'N', 'K', 'S', 'C', 'E', 'N', 'E'};

typedef struct entry {
    char name[FMU_RESOURCE_NAME];
    uint32_t code;
    uint32_t size;
    uint64_t count;
    uint64_t offset;
} entry;

struct fmu_resource {
    char *path;
    unsigned char *bytes;   /* the whole file */
    size_t size;
    size_t n_entries;
    entry *entries;         /* copied out of the file's table */
};

#if defined __GNUC__
static int fail(char *msg, size_t n, const char *format, ...) __attribute__((format(printf, 3, 4)));
#endif

static int fail(char *msg, size_t n, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(msg, n, format, args);
    va_end(args);
    return -1;
}

/* ---- the location -------------------------------------------------------------------------------- */

static int hex_digit(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* A Windows drive, "C:" (<ctype.h>'s isalpha would follow the C locale of the host's process) */
static int is_drive(const char *p)
{
    return ((p[0] >= 'A' && p[0] <= 'Z') || (p[0] >= 'a' && p[0] <= 'z')) && p[1] == ':';
}

int fmu_resource_folder_of_uri(const char *uri, char *folder, size_t n, char *msg, size_t n_msg)
{
    if (uri == NULL || uri[0] == '\0')
        return fail(msg, n_msg, "fmuResourceLocation is %s: this FMU reads its scene from resources/" FMU_RESOURCE_FILE
                    " and needs the location of the unzipped FMU's resources folder (a file: URI)",
                    uri ? "empty" : "NULL");
    if (strncmp(uri, "file:", 5) != 0)
        return fail(msg, n_msg, "fmuResourceLocation \"%s\" is not a file: URI (file:///path/to/resources)", uri);
    const char *path = uri + 5;
    const char *unc_host = NULL;
    size_t unc_length = 0;
    if (strncmp(path, "//", 2) == 0) {
        const char *authority = path + 2, *end = strchr(authority, '/');
        const size_t length = end ? (size_t)(end - authority) : strlen(authority);
        if (length == 0 || (length == 9 && strncmp(authority, "localhost", 9) == 0)) {
            path = authority + length;
        } else if (length == 2 && is_drive(authority)) {
            path = authority;  /* file://C:/path, as some hosts write it: the drive's path */
        } else {
#ifdef _WIN32
            unc_host = authority;
            unc_length = length;
            path = authority + length;
#else
            return fail(msg, n_msg, "fmuResourceLocation \"%s\" names the host \"%.*s\": only a local folder "
                        "(file:///path) can be read", uri, (int)length, authority);
#endif
        }
    }
    if (path[0] != '/' && !is_drive(path))
        return fail(msg, n_msg, "fmuResourceLocation \"%s\" has no absolute path (file:///path/to/resources)", uri);
    size_t k = 0;
    if (unc_host) {  /* \\server\share\...: the host, then the path */
        if (unc_length + 3 > n) return fail(msg, n_msg, "fmuResourceLocation \"%s\" is too long", uri);
        folder[k++] = '/';
        folder[k++] = '/';
        memcpy(folder + k, unc_host, unc_length);
        k += unc_length;
    }
    for (const char *p = path; *p; p++) {
        int c = (unsigned char)*p;
        /* %XY is the byte XY; a % not followed by two hexadecimal digits is itself (a host that writes the path as it
           is, unencoded), but %00 would end the path early */
        const int hi = c == '%' ? hex_digit((unsigned char)p[1]) : -1, lo = hi < 0 ? -1 : hex_digit((unsigned char)p[2]);
        if (hi == 0 && lo == 0)
            return fail(msg, n_msg, "fmuResourceLocation \"%s\" has %%00 (a NUL character) in its path", uri);
        if (hi >= 0 && lo >= 0) {
            c = 16 * hi + lo;
            p += 2;
        }
        if (k + 1 >= n) return fail(msg, n_msg, "fmuResourceLocation \"%s\" is too long", uri);
        folder[k++] = (char)c;
    }
    folder[k] = '\0';
#ifdef _WIN32
    if (folder[0] == '/' && is_drive(folder + 1)) memmove(folder, folder + 1, k);  /* /C:/path is C:/path */
#endif
    return 0;
}

/* ---- the file ------------------------------------------------------------------------------------ */

static uint32_t get_u32(const unsigned char *p)
{
    uint32_t x;
    memcpy(&x, p, sizeof x);
    return x;
}

static uint64_t get_u64(const unsigned char *p)
{
    uint64_t x;
    memcpy(&x, p, sizeof x);
    return x;
}

/* CRC-32 (ISO-HDLC, zlib's crc32): the same number Python's zlib.crc32 gives the writer. Eight bytes a step
   ("slicing by 8": table k gives the CRC of a byte followed by k zero bytes), a 100,000-link chain's 64 MB in a
   few tens of milliseconds. */
static uint32_t crc32_of(const unsigned char *p, size_t n)
{
    static const int slices = 8;
    uint32_t table[8][256];
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int j = 0; j < 8; j++) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        table[0][i] = c;
    }
    for (int k = 1; k < slices; k++)
        for (uint32_t i = 0; i < 256; i++) table[k][i] = (table[k - 1][i] >> 8) ^ table[0][table[k - 1][i] & 0xFFu];
    uint32_t crc = 0xFFFFFFFFu;
    for (; n >= 8; p += 8, n -= 8) {
        const uint32_t low = crc ^ ((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24);
        crc = table[7][low & 0xFFu] ^ table[6][(low >> 8) & 0xFFu] ^ table[5][(low >> 16) & 0xFFu] ^ table[4][low >> 24]
              ^ table[3][p[4]] ^ table[2][p[5]] ^ table[1][p[6]] ^ table[0][p[7]];
    }
    for (; n > 0; p++, n--) crc = table[0][(crc ^ *p) & 0xFFu] ^ (crc >> 8);
    return crc ^ 0xFFFFFFFFu;
}

static size_t code_size(uint32_t code)
{
    switch (code) {
    case 'q': case 'd': case 'Q': return 8;
    case 'i': return 4;
    case 'B': case 'c': return 1;
    default: return 0;
    }
}

void fmu_resource_free(fmu_resource *r)
{
    if (!r) return;
    free(r->path);
    free(r->bytes);
    free(r->entries);
    free(r);
}

const char *fmu_resource_path(const fmu_resource *r) { return r->path; }

/* Why the file's bytes are not a resource this reader takes, or NULL; the entries copied into r. */
static const char *check(fmu_resource *r, char *why, size_t n)
{
    const unsigned char *b = r->bytes;
    const uint64_t n_entries = get_u32(b + 24);
    if (get_u32(b + 28) != ENTRY_SIZE) {
        snprintf(why, n, "its entries are %u bytes long, this FMU's reader takes %d", (unsigned)get_u32(b + 28),
                 ENTRY_SIZE);
        return why;
    }
    if (n_entries > (r->size - HEADER_SIZE) / ENTRY_SIZE) return "its table of entries runs past its end";
    const uint32_t crc = crc32_of(b + HEADER_SIZE, r->size - HEADER_SIZE);
    if (crc != get_u32(b + 32)) {
        snprintf(why, n, "its checksum does not match its contents (CRC-32 0x%08x, the header says 0x%08x): the file "
                 "is damaged", (unsigned)crc, (unsigned)get_u32(b + 32));
        return why;
    }
    r->n_entries = (size_t)n_entries;
    r->entries = calloc(r->n_entries ? r->n_entries : 1, sizeof(entry));
    if (!r->entries) return "out of memory";
    const uint64_t data_start = HEADER_SIZE + (uint64_t)ENTRY_SIZE * n_entries;
    for (size_t i = 0; i < r->n_entries; i++) {
        const unsigned char *p = b + HEADER_SIZE + ENTRY_SIZE * i;
        entry *e = &r->entries[i];
        memcpy(e->name, p, FMU_RESOURCE_NAME);
        e->code = get_u32(p + 40);
        e->size = get_u32(p + 44);
        e->count = get_u64(p + 48);
        e->offset = get_u64(p + 56);
        if (memchr(e->name, '\0', FMU_RESOURCE_NAME) == NULL || e->name[0] == '\0') {
            snprintf(why, n, "entry %zu has no name", i + 1);
            return why;
        }
        if (code_size(e->code) == 0 || code_size(e->code) != e->size) {
            snprintf(why, n, "entry %s has the type code %u and elements of %u bytes, which this reader does not know",
                     e->name, (unsigned)e->code, (unsigned)e->size);
            return why;
        }
        if (e->count > (r->size - data_start) / e->size || e->offset % 8 != 0 || e->offset < data_start
            || e->offset > r->size || e->count * e->size > r->size - e->offset) {
            snprintf(why, n, "entry %s (%llu elements at byte %llu) lies outside the file's data", e->name,
                     (unsigned long long)e->count, (unsigned long long)e->offset);
            return why;
        }
        for (size_t j = 0; j < i; j++)
            if (strcmp(r->entries[j].name, e->name) == 0) {
                snprintf(why, n, "entry %s is there twice", e->name);
                return why;
            }
    }
    return NULL;
}

fmu_resource *fmu_resource_load(const char *folder, char *msg, size_t n_msg)
{
    fmu_resource *r = calloc(1, sizeof *r);
    const size_t length = strlen(folder);
    if (r) r->path = malloc(length + sizeof("/" FMU_RESOURCE_FILE));
    if (!r || !r->path) {
        fmu_resource_free(r);
        fail(msg, n_msg, "out of memory");
        return NULL;
    }
    const int separated = length > 0 && (folder[length - 1] == '/' || folder[length - 1] == '\\');
    snprintf(r->path, length + sizeof("/" FMU_RESOURCE_FILE), "%s%s" FMU_RESOURCE_FILE, folder, separated ? "" : "/");
    FILE *f = fopen(r->path, "rb");
    if (!f) {
        fail(msg, n_msg, "the scene's resource %s (the FMU's resources/" FMU_RESOURCE_FILE ") cannot be opened: it is "
             "missing or not readable (is fmuResourceLocation the unzipped FMU's resources folder?)", r->path);
        fmu_resource_free(r);
        return NULL;
    }
    unsigned char header[HEADER_SIZE];
    const size_t got = fread(header, 1, HEADER_SIZE, f);
    const char *problem = NULL;
    char why[512];
    uint64_t declared = 0;
    if (got < HEADER_SIZE || memcmp(header, magic, sizeof magic) != 0) {
        problem = got < HEADER_SIZE ? "it is shorter than the header of a linknet scene resource"
                                    : "it is not a linknet scene resource (no LNKSCENE at its start)";
    } else if (get_u32(header + 12) != BYTE_ORDER_MARK) {
        problem = "it was written for a machine of another byte order";
    } else if (get_u32(header + 8) != FMU_RESOURCE_FORMAT) {
        snprintf(why, sizeof why, "it is of format version %u, this FMU's binary reads version %d (the binary and "
                 "the resource come from different linknet releases: build the FMU again)",
                 (unsigned)get_u32(header + 8), FMU_RESOURCE_FORMAT);
        problem = why;
    } else {
        declared = get_u64(header + 16);
        if (declared < HEADER_SIZE || declared > (uint64_t)(size_t)-1 / 2) problem = "its header gives no valid size";
    }
    if (!problem) {
        r->size = (size_t)declared;
        r->bytes = malloc(r->size);
        if (!r->bytes) {
            snprintf(why, sizeof why, "out of memory for its %llu bytes", (unsigned long long)declared);
            problem = why;
        } else {
            memcpy(r->bytes, header, HEADER_SIZE);
            const size_t rest = fread(r->bytes + HEADER_SIZE, 1, r->size - HEADER_SIZE, f);
            unsigned char extra;
            if (rest < r->size - HEADER_SIZE) {
                snprintf(why, sizeof why, "it is truncated: its header says %llu bytes, it has %llu",
                         (unsigned long long)declared, (unsigned long long)(HEADER_SIZE + rest));
                problem = why;
            } else if (fread(&extra, 1, 1, f) == 1) {
                snprintf(why, sizeof why, "it is longer than the %llu bytes its header says",
                         (unsigned long long)declared);
                problem = why;
            } else {
                problem = check(r, why, sizeof why);
            }
        }
    }
    fclose(f);
    if (problem) {
        fail(msg, n_msg, "the scene's resource %s cannot be read: %s", r->path, problem);
        fmu_resource_free(r);
        return NULL;
    }
    return r;
}

/* ---- entries ------------------------------------------------------------------------------------- */

static const entry *find(const fmu_resource *r, const char *name)
{
    for (size_t i = 0; i < r->n_entries; i++)
        if (strcmp(r->entries[i].name, name) == 0) return &r->entries[i];
    return NULL;
}

int fmu_resource_entry(const fmu_resource *r, const char *name, const void **data, char *code, size_t *size,
                       uint64_t *count)
{
    const entry *e = find(r, name);
    if (!e) return -1;
    if (data) *data = e->count ? r->bytes + e->offset : NULL;
    if (code) *code = (char)e->code;
    if (size) *size = e->size;
    if (count) *count = e->count;
    return 0;
}

size_t fmu_resource_entries_with_prefix(const fmu_resource *r, const char *prefix)
{
    const size_t n = strlen(prefix);
    size_t found = 0;
    for (size_t i = 0; i < r->n_entries; i++) found += strncmp(r->entries[i].name, prefix, n) == 0;
    return found;
}

static const entry *typed(const fmu_resource *r, const char *name, char code, size_t size, char *msg, size_t n_msg)
{
    const entry *e = find(r, name);
    if (!e) {
        fail(msg, n_msg, "the scene's resource %s has no entry %s (a resource of another linknet release: build the "
             "FMU again)", r->path, name);
        return NULL;
    }
    if (e->code != (uint32_t)(unsigned char)code || e->size != size) {
        fail(msg, n_msg, "the scene's resource %s: entry %s has elements of type '%c' and %u bytes, this FMU reads "
             "'%c' of %zu bytes", r->path, name, (char)e->code, (unsigned)e->size, code, size);
        return NULL;
    }
    return e;
}

int fmu_resource_array(const fmu_resource *r, const char *name, char code, size_t size, int64_t count, int absent_ok,
                       const void **data, char *msg, size_t n_msg)
{
    const entry *e = typed(r, name, code, size, msg, n_msg);
    if (!e) return -1;
    if (!(absent_ok && e->count == 0) && (count < 0 || e->count != (uint64_t)count))
        return fail(msg, n_msg, "the scene's resource %s: entry %s has %llu elements, the scene's sizes give %lld",
                    r->path, name, (unsigned long long)e->count, (long long)count);
    *data = e->count ? r->bytes + e->offset : NULL;
    return 0;
}

int fmu_resource_scalar(const fmu_resource *r, const char *name, char code, size_t size, void *out, char *msg,
                        size_t n_msg)
{
    const void *data = NULL;
    if (fmu_resource_array(r, name, code, size, 1, 0, &data, msg, n_msg) != 0) return -1;
    memcpy(out, data, size);
    return 0;
}

int fmu_resource_texts(const fmu_resource *r, const char *name, int64_t count, const char ***texts, char *msg,
                       size_t n_msg)
{
    const entry *e = typed(r, name, 'c', 1, msg, n_msg);
    if (!e) return -1;
    const char *p = (const char *)r->bytes + e->offset, *end = p + e->count;
    int64_t found = 0;
    for (const char *q = p; q < end; q++) found += *q == '\0';
    if (count < 0 || found != count || (e->count && end[-1] != '\0'))
        return fail(msg, n_msg, "the scene's resource %s: entry %s holds %lld texts%s, the scene's sizes give %lld",
                    r->path, name, (long long)found, e->count && end[-1] != '\0' ? " and an unended one" : "",
                    (long long)count);
    *texts = malloc((size_t)(count > 0 ? count : 1) * sizeof **texts);
    if (!*texts) return fail(msg, n_msg, "out of memory");
    for (int64_t i = 0; i < count; i++) {
        (*texts)[i] = p;
        p += strlen(p) + 1;
    }
    return 0;
}
