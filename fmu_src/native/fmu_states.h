/* FMU states as the native FMUs' FMI glue hands them out, whatever the FMI version: a block of bytes with a header
 * (format version, byte order, the model's fingerprint, size, the instance's mode, and when serialized a checksum)
 * followed by the model's own bytes (fmu_model.h), and the registry of the states one instance made and has not
 * freed. Also the memory of the last discarded step, by which a step asked again from the very state it failed from
 * is answered without being computed (the model is deterministic: it would fail the same way).
 *
 * Only FMI-independent rules live here, with the one text both glues log for a repeated step (REPEATED_STEP): each
 * glue (fmi2Functions.c, fmi3Functions.c) says the other words, with its own function names, and maps the results onto
 * its status codes. Everything is static: each glue compiles its own copy, nothing is exported.
 */
#ifndef LINKNET_FMU_STATES_H
#define LINKNET_FMU_STATES_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_model.h"

#define FMU_STATE_FORMAT 6u  /* 5: the ropes' mode and impulses are part of the model's state; 6: friction's
                                   slip references too */
#define FMU_STATE_BYTE_ORDER 0x01020304u

typedef struct fmu_state_header {
    char magic[8];          /* "LNKFMUST" */
    uint32_t format;        /* FMU_STATE_FORMAT */
    uint32_t byte_order;    /* FMU_STATE_BYTE_ORDER as the writer stored it */
    uint64_t fingerprint;   /* the model's: which FMU build wrote the state */
    uint64_t size;          /* bytes, this header included */
    uint32_t mode;          /* the instance's mode when the state was taken */
    uint32_t reserved;
    uint64_t reserved2;     /* 0 (the instance's registry, not the state, says which handles are live) */
    uint64_t checksum;      /* serialized: FNV-1a of the bytes after the header (0 in memory) */
} fmu_state_header;

static inline const char *fmu_state_magic(void) { return "LNKFMUST"; }

/* FNV-1a, 64 bits: a serialized state damaged in storage or transit is refused rather than run. */
static inline uint64_t fmu_state_checksum(const unsigned char *p, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

static inline size_t fmu_state_size(const fmu_model *model)
{
    return sizeof(fmu_state_header) + fmu_model_state_size(model);
}

/* Why the n bytes of header h (and after it) are not a state of this FMU's model, or NULL. */
static inline const char *fmu_state_problem(const fmu_model *model, const fmu_state_header *h, size_t n,
                                            uint32_t last_mode)
{
    if (n < sizeof *h || memcmp(h->magic, fmu_state_magic(), sizeof h->magic) != 0) return "not a linknet FMU state";
    if (h->byte_order != FMU_STATE_BYTE_ORDER) return "a state written on a machine of another byte order";
    if (h->format != FMU_STATE_FORMAT) return "a state of another format version (another linknet FMU release)";
    if (h->fingerprint != fmu_model_info_get(model)->fingerprint)
        return "a state of another FMU (its scene fingerprint differs: another scene, other options, another FMI "
               "version or another build)";
    if (h->size != fmu_state_size(model) || h->size != n) return "a state of the wrong size";
    if (h->mode > last_mode) return "a state with an invalid mode";
    return NULL;
}

/* The model's state now, with its header, into h (fmu_state_size(model) bytes). */
static inline void fmu_state_write(fmu_state_header *h, const fmu_model *model, uint32_t mode)
{
    memcpy(h->magic, fmu_state_magic(), sizeof h->magic);
    h->format = FMU_STATE_FORMAT;
    h->byte_order = FMU_STATE_BYTE_ORDER;
    h->fingerprint = fmu_model_info_get(model)->fingerprint;
    h->size = fmu_state_size(model);
    h->mode = mode;
    h->reserved = 0;
    h->reserved2 = 0;
    h->checksum = 0;
    fmu_model_state_save(model, (unsigned char *)(h + 1));
}

/* A live state's bytes as they travel: the header with the checksum of the contents, then the contents. */
static inline void fmu_state_serialize(const fmu_state_header *h, unsigned char *out)
{
    memcpy(out, h, (size_t)h->size);
    fmu_state_header copy;
    memcpy(&copy, h, sizeof copy);
    copy.checksum = fmu_state_checksum((const unsigned char *)(h + 1), (size_t)h->size - sizeof *h);
    memcpy(out, &copy, sizeof copy);
}

/* Why `size` serialized bytes are not a state of this FMU (header, identity, checksum), or NULL. */
static inline const char *fmu_state_serialized_problem(const fmu_model *model, const unsigned char *bytes,
                                                       size_t size, uint32_t last_mode)
{
    fmu_state_header header;
    memset(&header, 0, sizeof header);
    memcpy(&header, bytes, size < sizeof header ? size : sizeof header);
    const char *problem = fmu_state_problem(model, &header, size, last_mode);
    if (problem) return problem;
    if (header.checksum != fmu_state_checksum(bytes + sizeof header, size - sizeof header))
        return "the state's bytes are damaged (checksum mismatch)";
    return NULL;
}

/* ---- the registry of the states an instance handed out and has not freed --------------------------------------
   A handle is live exactly when it is listed: whether one is, is decided by comparing pointers, never by reading
   through the handle, so a made-up, freed or foreign handle is refused without touching the memory it points to (a
   mark written into a state before free() could not tell either: the compiler may drop that store, and the block may
   be reused or unmapped). */
typedef struct fmu_state_registry {
    fmu_state_header **states;
    size_t n, capacity;
} fmu_state_registry;

static inline size_t fmu_state_index(const fmu_state_registry *r, const void *handle)
{
    for (size_t i = 0; i < r->n; i++)
        if ((const void *)r->states[i] == handle) return i;
    return r->n;
}

static inline int fmu_state_is_live(const fmu_state_registry *r, const void *handle)
{
    return handle != NULL && fmu_state_index(r, handle) < r->n;
}

/* 1, or 0 where there is no memory to list it (the caller frees h). */
static inline int fmu_state_remember(fmu_state_registry *r, fmu_state_header *h)
{
    if (r->n == r->capacity) {
        const size_t capacity = r->capacity ? 2 * r->capacity : 8;
        fmu_state_header **grown = realloc(r->states, capacity * sizeof *grown);
        if (grown == NULL) return 0;
        r->states = grown;
        r->capacity = capacity;
    }
    r->states[r->n++] = h;
    return 1;
}

/* Frees the i-th listed state and forgets it. */
static inline void fmu_state_free_at(fmu_state_registry *r, size_t i)
{
    free(r->states[i]);
    r->states[i] = r->states[--r->n];
}

static inline void fmu_state_free_all(fmu_state_registry *r)
{
    for (size_t i = 0; i < r->n; i++) free(r->states[i]);
    free(r->states);
    r->states = NULL;
    r->n = r->capacity = 0;
}

/* ---- the last discarded step --------------------------------------------------------------------------------- */
/* What a glue logs when the step asked is the one discarded last, from the same state (printf: t, h). */
#define REPEATED_STEP                                                                                            \
    "the step from t=%.17g with h=%.17g was discarded before, from this same state with these same inputs, so it "\
    "fails again the same way (not computed again); stop here, or set other inputs, restore another state or take " \
    "a shorter step."
typedef struct fmu_discard_memory {
    int discarded;                      /* a step is remembered */
    double t, h;
    unsigned char *from;                /* the model's state bytes it was discarded from (fmu_model_state_save) */
    unsigned char *now;                 /* scratch: the model's state bytes now, to compare */
    char reason[FMU_MESSAGE];           /* what the model said when it discarded that step */
} fmu_discard_memory;

/* The step from t with h was discarded from the model's present state, for `reason`: remembered with that state's
   bytes (not remembered where there is no memory for them: a repeat is then computed again). */
static inline void fmu_discard_remember(fmu_discard_memory *d, const fmu_model *model, double t, double h,
                                        const char *reason)
{
    const size_t n = fmu_model_state_size(model);
    if (d->from == NULL) {
        d->from = malloc(n ? n : 1);
        d->now = malloc(n ? n : 1);
    }
    d->discarded = d->from != NULL && d->now != NULL;
    if (!d->discarded) return;
    d->t = t;
    d->h = h;
    fmu_model_state_save(model, d->from);
    snprintf(d->reason, sizeof d->reason, "%s", reason);
}

/* Whether the step from t with h is the one discarded last, asked again from the same model state. */
static inline int fmu_discard_is_repeat(fmu_discard_memory *d, const fmu_model *model, double t, double h)
{
    if (!d->discarded || t != d->t || h != d->h) return 0;
    fmu_model_state_save(model, d->now);
    return memcmp(d->now, d->from, fmu_model_state_size(model)) == 0;
}

static inline void fmu_discard_free(fmu_discard_memory *d)
{
    free(d->from);
    free(d->now);
    d->from = d->now = NULL;
    d->discarded = 0;
}

#endif
