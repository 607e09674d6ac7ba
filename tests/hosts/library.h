/* Loading an FMU's binary in the plain C test hosts (fmu_host.c, fmi3_host.c): dlopen natively, LoadLibrary
 * when built with mingw-w64 (run under Wine), so one host runs on both platforms' binaries. */
#ifndef PENDULAB_TEST_LIBRARY_H
#define PENDULAB_TEST_LIBRARY_H
#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
#endif
#endif
