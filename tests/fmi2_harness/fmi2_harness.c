/* fmi2_harness: plays a plan of FMI 2.0 co-simulation calls on one FMU binary.
 *
 *   fmi2_harness < plan
 *
 * The plan, one call per line (strings and paths are the rest of the line, UTF-8):
 *   load PATH              load the binary, resolve all 34 fmi2 functions (exit 2 if one is missing)
 *   instantiate GUID URI   fmi2Instantiate(fmi2CoSimulation, resource location URI), logging on
 *   setup T0               fmi2SetupExperiment without tolerance or stop time
 *   enter | exit           fmi2EnterInitializationMode | fmi2ExitInitializationMode
 *   real VR X | int VR N | string VR TEXT      fmi2SetReal | fmi2SetInteger | fmi2SetString
 *   step T H               fmi2DoStep(T, H, fmi2True)
 *   get VR... | geti VR... fmi2GetReal | fmi2GetInteger, printed as "= VR VALUE ..." (%.17g)
 *   save | restore         fmi2GetFMUstate + serialize + free; deserialize + fmi2SetFMUstate + free
 *   reset | free           fmi2Reset | fmi2FreeInstance
 * Prints "CALL STATUS" per call and "log STATUS CATEGORY: MESSAGE" per logged message, then
 * "done" at the end: the tests read this output, not only the exit status (a wine process can
 * exit oddly after having finished). Exit status: 0, or 1 on a malformed plan, 2 on a load error. */
#ifdef _WIN32
#define __USE_MINGW_ANSI_STDIO 1 /* C99 printf of doubles, as glibc's */
#include <fcntl.h>
#include <io.h>
#include <windows.h>
#else
#include <dlfcn.h>
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define FMI2_FUNCTIONS(X)       \
    X(GetTypesPlatform)         \
    X(GetVersion)               \
    X(SetDebugLogging)          \
    X(Instantiate)              \
    X(FreeInstance)             \
    X(SetupExperiment)          \
    X(EnterInitializationMode)  \
    X(ExitInitializationMode)   \
    X(Terminate)                \
    X(Reset)                    \
    X(GetReal)                  \
    X(GetInteger)               \
    X(GetBoolean)               \
    X(GetString)                \
    X(SetReal)                  \
    X(SetInteger)               \
    X(SetBoolean)               \
    X(SetString)                \
    X(GetFMUstate)              \
    X(SetFMUstate)              \
    X(FreeFMUstate)             \
    X(SerializedFMUstateSize)   \
    X(SerializeFMUstate)        \
    X(DeSerializeFMUstate)      \
    X(GetDirectionalDerivative) \
    X(SetRealInputDerivatives)  \
    X(GetRealOutputDerivatives) \
    X(DoStep)                   \
    X(CancelStep)               \
    X(GetStatus)                \
    X(GetRealStatus)            \
    X(GetIntegerStatus)         \
    X(GetBooleanStatus)         \
    X(GetStringStatus)

static struct {
#define X(f) fmi2##f##TYPE* f;
    FMI2_FUNCTIONS(X)
#undef X
} fmi;

static const char* status_name(fmi2Status s) {
    static const char* names[] = {"fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending"};
    return (s >= 0 && s <= fmi2Pending) ? names[s] : "invalid-status";
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    (void)instance;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    printf("log %s %s: %s\n", status_name(status), category ? category : "", text);
}

static int load(const char* path) {
#ifdef _WIN32
    wchar_t wide[4096]; /* the path is UTF-8: LoadLibraryA would read it in the ANSI code page */
    if (!MultiByteToWideChar(CP_UTF8, 0, path, -1, wide, 4096)) return 0;
    HMODULE lib = LoadLibraryW(wide);
    if (!lib) {
        printf("load-error %lu\n", (unsigned long)GetLastError());
        return 0;
    }
#define RESOLVE(name) (void*)GetProcAddress(lib, name)
#else
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        printf("load-error %s\n", dlerror());
        return 0;
    }
#define RESOLVE(name) dlsym(lib, name)
#endif
    int found = 0, missing = 0;
#define X(f)                                \
    {                                       \
        void* p = RESOLVE("fmi2" #f);       \
        memcpy(&fmi.f, &p, sizeof p);       \
        if (p)                              \
            ++found;                        \
        else {                              \
            printf("missing fmi2%s\n", #f); \
            ++missing;                      \
        }                                   \
    }
    FMI2_FUNCTIONS(X)
#undef X
    printf("symbols %d\n", found);
    return missing == 0;
}

static char* rest_of_line(char* s) { /* after the first word; trailing newline removed */
    s += strspn(s, " ");
    s += strcspn(s, " \r\n");
    s += strspn(s, " ");
    s[strcspn(s, "\r\n")] = '\0';
    return s;
}

int main(void) {
#ifdef _WIN32
    _setmode(_fileno(stdout), _O_BINARY); /* "\n" as on Linux */
#endif
    setvbuf(stdout, NULL, _IOLBF, 0);
    static char line[8192];
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = NULL;
    char* saved = NULL;
    size_t saved_size = 0;
    int loaded = 0;
    while (fgets(line, sizeof line, stdin)) {
        char word[32] = "";
        if (sscanf(line, "%31s", word) != 1 || word[0] == '#') continue;
        char* rest = rest_of_line(line);
        if (strcmp(word, "load") == 0) {
            loaded = load(rest);
            if (!loaded) return 2;
            continue;
        }
        if (!loaded) {
            printf("plan-error: load first\n");
            return 1;
        }
        fmi2Status st = fmi2OK;
        if (strcmp(word, "instantiate") == 0) {
            char guid[256];
            if (sscanf(rest, "%255s", guid) != 1) return printf("plan-error: %s", line), 1;
            c = fmi.Instantiate("harness", fmi2CoSimulation, guid, rest_of_line(rest), &callbacks, fmi2False, fmi2True);
            printf("instantiate %s\n", c ? "ok" : "NULL");
            continue;
        } else if (strcmp(word, "setup") == 0) {
            st = fmi.SetupExperiment(c, fmi2False, 0.0, strtod(rest, NULL), fmi2False, 0.0);
        } else if (strcmp(word, "enter") == 0) {
            st = fmi.EnterInitializationMode(c);
        } else if (strcmp(word, "exit") == 0) {
            st = fmi.ExitInitializationMode(c);
        } else if (strcmp(word, "real") == 0 || strcmp(word, "int") == 0) {
            unsigned vr;
            double x;
            if (sscanf(rest, "%u %lf", &vr, &x) != 2) return printf("plan-error: %s", line), 1;
            if (word[0] == 'r') {
                st = fmi.SetReal(c, &vr, 1, &x);
            } else {
                fmi2Integer n = (fmi2Integer)x;
                st = fmi.SetInteger(c, &vr, 1, &n);
            }
        } else if (strcmp(word, "string") == 0) {
            unsigned vr;
            if (sscanf(rest, "%u", &vr) != 1) return printf("plan-error: %s", line), 1;
            fmi2String text = rest_of_line(rest);
            st = fmi.SetString(c, &vr, 1, &text);
        } else if (strcmp(word, "step") == 0) {
            double t, h;
            if (sscanf(rest, "%lf %lf", &t, &h) != 2) return printf("plan-error: %s", line), 1;
            st = fmi.DoStep(c, t, h, fmi2True);
        } else if (strcmp(word, "get") == 0 || strcmp(word, "geti") == 0) {
            char* p = rest;
            char* end;
            printf("=");
            for (unsigned long vr = strtoul(p, &end, 10); end != p; vr = strtoul(p, &end, 10)) {
                p = end;
                fmi2ValueReference ref = (fmi2ValueReference)vr;
                if (word[3] == 'i') {
                    fmi2Integer n = 0;
                    st = fmi.GetInteger(c, &ref, 1, &n);
                    printf(" %u %d", ref, (int)n);
                } else {
                    fmi2Real x = 0.0;
                    st = fmi.GetReal(c, &ref, 1, &x);
                    printf(" %u %.17g", ref, x);
                }
                if (st != fmi2OK) break;
            }
            printf("\n");
        } else if (strcmp(word, "save") == 0) {
            fmi2FMUstate s = NULL;
            st = fmi.GetFMUstate(c, &s);
            if (st == fmi2OK) st = fmi.SerializedFMUstateSize(c, s, &saved_size);
            if (st == fmi2OK) {
                free(saved);
                saved = malloc(saved_size);
                st = fmi.SerializeFMUstate(c, s, saved, saved_size);
            }
            if (s) fmi.FreeFMUstate(c, &s);
        } else if (strcmp(word, "restore") == 0) {
            fmi2FMUstate s = NULL;
            st = fmi.DeSerializeFMUstate(c, saved, saved_size, &s);
            if (st == fmi2OK) st = fmi.SetFMUstate(c, s);
            if (s) fmi.FreeFMUstate(c, &s);
        } else if (strcmp(word, "reset") == 0) {
            st = fmi.Reset(c);
        } else if (strcmp(word, "free") == 0) {
            if (c) fmi.FreeInstance(c);
            c = NULL;
        } else {
            printf("plan-error: unknown call %s\n", word);
            return 1;
        }
        printf("%s %s\n", word, status_name(st));
    }
    if (c) fmi.FreeInstance(c);
    free(saved);
    printf("done\n");
    return 0;
}
