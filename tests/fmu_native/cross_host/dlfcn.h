/* <dlfcn.h> for tests/fmu_native/native_host.c cross-built for another platform (test_native_platforms.py puts this
 * folder first on the include path). native_host.c opens binaries/linux64/<id>.so; this dlopen opens the FMU's binary
 * of the platform the host is built for instead, binaries/FMU_PLATFORM_FOLDER/<id>FMU_LIBRARY_SUFFIX, so the host
 * runs the shipped layout unchanged. On Windows dlopen, dlsym and dlerror are LoadLibraryA, GetProcAddress and the
 * error code (no <windows.h>: its GUID type would clash with the host's variable of that name).
 */
#ifndef NATIVE_HOST_CROSS_DLFCN_H
#define NATIVE_HOST_CROSS_DLFCN_H
#if !defined(FMU_PLATFORM_FOLDER) || !defined(FMU_LIBRARY_SUFFIX)
#error "define FMU_PLATFORM_FOLDER (e.g. \"win64\") and FMU_LIBRARY_SUFFIX (e.g. \".dll\")"
#endif
#include <stdio.h>
#include <string.h>

/* DIR/binaries/linux64/ID.so -> DIR/binaries/FMU_PLATFORM_FOLDER/ID FMU_LIBRARY_SUFFIX, with the separator sep */
static const char *cross_library_path(const char *path, char sep)
{
    static char out[4200];
    const char *asked = strstr(path, "/binaries/linux64/");
    const size_t n = strlen(path);
    if (asked == NULL || n < 3 || strcmp(path + n - 3, ".so") != 0 || n + 64 > sizeof out) return path;
    snprintf(out, sizeof out, "%.*s/binaries/%s/%.*s%s", (int)(asked - path), path, FMU_PLATFORM_FOLDER,
             (int)(n - 3 - (size_t)(asked - path) - strlen("/binaries/linux64/")), asked + strlen("/binaries/linux64/"),
             FMU_LIBRARY_SUFFIX);
    for (char *c = out; *c; c++)
        if (*c == '/') *c = sep;
    return out;
}

#ifdef _WIN32
#define RTLD_NOW 2
#define RTLD_LOCAL 0
__declspec(dllimport) void *__stdcall LoadLibraryA(const char *name);
__declspec(dllimport) void *__stdcall GetProcAddress(void *module, const char *name);
__declspec(dllimport) unsigned long __stdcall GetLastError(void);
static char cross_dl_message[4400];
static void *dlopen(const char *path, int flags)
{
    (void)flags;
    const char *library = cross_library_path(path, '\\');
    void *module = LoadLibraryA(library);
    if (module == NULL)
        snprintf(cross_dl_message, sizeof cross_dl_message, "LoadLibraryA(%s) failed: error %lu", library,
                 GetLastError());
    return module;
}
static void *dlsym(void *module, const char *name) { return GetProcAddress(module, name); }
static char *dlerror(void) { return cross_dl_message; }
#else
#include_next <dlfcn.h>
static void *cross_dlopen(const char *path, int flags) { return dlopen(cross_library_path(path, '/'), flags); }
#define dlopen cross_dlopen
#endif

#endif
