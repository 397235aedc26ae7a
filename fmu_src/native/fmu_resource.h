/* The native FMU's resource file: the scene as data, read at instantiation from the folder FMI names (resources/ of
 * the unzipped FMU), so that the FMU's binaries and sources are the same for every scene.
 *
 * The file, FMU_RESOURCE_FILE in that folder, is written by fmu_src/native/build.py (fmu_src/native/README.md
 * describes it): a header, a table of named entries, then their data. Each entry is one array of one type (a
 * scalar is an array of one entry) and is read in place. Everything after the header is covered by a CRC-32, so
 * a file damaged in storage or transit is refused rather than run.
 *
 *   header (48 bytes)   "LNKSCENE", format (FMU_RESOURCE_FORMAT), byte order mark 0x01020304, file size,
 *                       entry count, entry size (64), CRC-32 of the bytes after the header, zeros
 *   entries (64 each)   name (40 bytes, NUL-terminated), type code, size of one element, element count, offset of
 *                       the data from the start of the file (a multiple of 8)
 *   data
 *
 * Type codes are Python's struct module's: 'q' int64, 'i' int32, 'd' double, 'B' uint8, 'Q' uint64, 'c' char
 * (a text, or a list of texts one after the other, each ending with a NUL). A reader accepts its own format only:
 * what an entry means is the reader's business (linknet_model.c, fmi3Functions.c), which refuses an entry of
 * another type, element size or count, naming it and the file.
 *
 * FMI glue, no physics: this reads and checks the file and hands out its entries by name.
 */
#ifndef LINKNET_FMU_RESOURCE_H
#define LINKNET_FMU_RESOURCE_H

#include <stddef.h>
#include <stdint.h>

#define FMU_RESOURCE_FILE "linknet_scene.bin"
#define FMU_RESOURCE_FORMAT 1
#define FMU_RESOURCE_NAME 40  /* bytes of an entry's name, its NUL included */

typedef struct fmu_resource fmu_resource;

/* The folder a file: URI names (FMI 2.0's fmuResourceLocation), into folder (n bytes): file:///path,
   file:/path and file://localhost/path, percent-encoding decoded (a % not followed by two hexadecimal digits taken
   as itself, as a host that does not encode writes it); on Windows file:///C:/path is C:/path and
   file://server/share/path is the share \\server\share\path. 0, or -1 with the reason in msg (n_msg bytes). */
int fmu_resource_folder_of_uri(const char *uri, char *folder, size_t n, char *msg, size_t n_msg);

/* The resource file in folder, read whole and checked (header, sizes, checksum, every entry inside the file), or
   NULL with the reason, naming the file, in msg (n_msg bytes). */
fmu_resource *fmu_resource_load(const char *folder, char *msg, size_t n_msg);
void fmu_resource_free(fmu_resource *r);

/* The file's path, for messages. */
const char *fmu_resource_path(const fmu_resource *r);

/* The entry called name: its data (NULL for none: count 0), type code, element size and count; 0, or -1 when the
   file has no such entry. */
int fmu_resource_entry(const fmu_resource *r, const char *name, const void **data, char *code, size_t *size,
                       uint64_t *count);

/* How many entries' names begin with prefix. */
size_t fmu_resource_entries_with_prefix(const fmu_resource *r, const char *prefix);

/* Checked reads, each 0 or -1 with the reason (naming the file, the entry and the rule) in msg, n_msg bytes:
   - the array `name` of type code (elements of `size` bytes) and `count` elements, pointed to in place (NULL for
     count 0); absent_ok: an entry of no elements stands for a NULL pointer, whatever count says;
   - a scalar copied into out;
   - a list of `count` NUL-terminated texts, pointers to each into *texts (allocated here, freed by the caller). */
int fmu_resource_array(const fmu_resource *r, const char *name, char code, size_t size, int64_t count, int absent_ok,
                       const void **data, char *msg, size_t n_msg);
int fmu_resource_scalar(const fmu_resource *r, const char *name, char code, size_t size, void *out, char *msg,
                        size_t n_msg);
int fmu_resource_texts(const fmu_resource *r, const char *name, int64_t count, const char ***texts, char *msg,
                       size_t n_msg);

#endif
