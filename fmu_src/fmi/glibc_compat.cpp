// Keeps an FMU's shared library loadable on older Linux distributions than the one it is built on
// (add_fmu links this file into every FMU and wraps the symbols below with `ld --wrap`), and makes
// the statically linked C++ runtime free its memory when the FMU is unloaded (at the end).
//
// Built on Debian 12 (glibc 2.36, GCC 12) with libstdc++ linked statically, the library would ask
// for these glibc symbol versions, newer than Ubuntu 20.04's 2.31 and RHEL 8's 2.28:
//   __libc_single_threaded  GLIBC_2.32  read by libstdc++'s headers (shared_ptr reference counts)
//   stat, fstat64           GLIBC_2.33  libstdc++ (basic_file, filesystem)
//   pthread_once            GLIBC_2.34  libstdc++ (locale initialisation, call_once)
//   hypot                   GLIBC_2.35  the model code (std::hypot)
//   exp, log, pow           GLIBC_2.29  the model code (SUNDIALS, iron loss); 2.29 is within
//                                       Ubuntu 20.04's 2.31 but not RHEL 8's 2.28
//   _dl_find_object         GLIBC_2.35  the unwinder of a static libgcc: avoided by linking
//                                       libgcc_s.so.1 dynamically (add_fmu), not here
// Each is redirected to the version every x86-64 glibc has (GLIBC_2.2.5) or defined here; the
// functions behave the same (the newer versions differ in errno handling or are new names of the
// same system call). tests/python/test_conformance.py checks the highest version the libraries
// need (readelf) and loads them with every symbol bound at once (LD_BIND_NOW).
#include <pthread.h>
#include <sys/stat.h>

#include <sched.h>
#include <atomic>

#define IPMSM_COMPAT_HIDDEN __attribute__((visibility("hidden")))

extern "C" {

// libstdc++ (GCC >= 11) reads this flag of glibc >= 2.32 to skip atomic operations while the
// process has one thread. Defined here, always 0 ("maybe several threads"): atomics always, which
// is what an older glibc gets anyway. Hidden: the FMU's own copy, never exported.
IPMSM_COMPAT_HIDDEN char __libc_single_threaded = 0;

// --- the old versions, by name@version ---
double ipmsm_compat_hypot(double, double);
__asm__(".symver ipmsm_compat_hypot, hypot@GLIBC_2.2.5");
double ipmsm_compat_exp(double);
__asm__(".symver ipmsm_compat_exp, exp@GLIBC_2.2.5");
double ipmsm_compat_log(double);
__asm__(".symver ipmsm_compat_log, log@GLIBC_2.2.5");
double ipmsm_compat_pow(double, double);
__asm__(".symver ipmsm_compat_pow, pow@GLIBC_2.2.5");

int ipmsm_compat_xstat(int, const char*, struct stat*);
__asm__(".symver ipmsm_compat_xstat, __xstat@GLIBC_2.2.5");

int ipmsm_compat_fxstat64(int, int, struct stat64*);
__asm__(".symver ipmsm_compat_fxstat64, __fxstat64@GLIBC_2.2.5");

// In glibc < 2.34 pthread_once lives in libpthread.so.0, which the host process may not have
// loaded: a weak reference, with a fallback below.
int ipmsm_compat_pthread_once(pthread_once_t*, void (*)(void)) __attribute__((weak));
__asm__(".symver ipmsm_compat_pthread_once, pthread_once@GLIBC_2.2.5");

// --- the wrappers (ld --wrap=NAME sends every reference to NAME here) ---
IPMSM_COMPAT_HIDDEN double __wrap_hypot(double x, double y) { return ipmsm_compat_hypot(x, y); }
IPMSM_COMPAT_HIDDEN double __wrap_exp(double x) { return ipmsm_compat_exp(x); }
IPMSM_COMPAT_HIDDEN double __wrap_log(double x) { return ipmsm_compat_log(x); }
IPMSM_COMPAT_HIDDEN double __wrap_pow(double x, double y) { return ipmsm_compat_pow(x, y); }

// _STAT_VER of x86-64 Linux: the kernel's struct stat layout, which is glibc's.
constexpr int kStatVer = 1;
IPMSM_COMPAT_HIDDEN int __wrap_stat(const char* path, struct stat* buf) {
    return ipmsm_compat_xstat(kStatVer, path, buf);
}
IPMSM_COMPAT_HIDDEN int __wrap_fstat64(int fd, struct stat64* buf) { return ipmsm_compat_fxstat64(kStatVer, fd, buf); }

IPMSM_COMPAT_HIDDEN int __wrap_pthread_once(pthread_once_t* once, void (*init)(void)) {
    if (ipmsm_compat_pthread_once != nullptr) return ipmsm_compat_pthread_once(once, init);
    // No libpthread in the process (glibc < 2.34): it cannot have started threads, but be exact
    // anyway: 0 not run, 1 running, 2 done.
    static_assert(sizeof(pthread_once_t) == sizeof(std::atomic<int>), "pthread_once_t is an int");
    auto* state = reinterpret_cast<std::atomic<int>*>(once);
    for (;;) {
        int expected = 0;
        if (state->compare_exchange_strong(expected, 1, std::memory_order_acquire)) {
            try {
                init();
            } catch (...) {
                state->store(0, std::memory_order_release);
                throw;
            }
            state->store(2, std::memory_order_release);
            return 0;
        }
        if (expected == 2) return 0;
        sched_yield();
    }
}

}  // extern "C"

// The libstdc++ linked into the FMU allocates its emergency exception-handling pool (about 70 KiB)
// when the library is loaded and never frees it: after fmi2's host unloads the FMU (dlclose, as
// fmpy does) that memory is lost, once per load. Freed here when the library is unloaded (or the
// process ends); nothing of the FMU runs after that. Only in the static-runtime build: with a
// shared libstdc++ (sanitizer builds) the pool is the process's.
namespace __gnu_cxx {
void __freeres() noexcept;
}
__attribute__((destructor(101), visibility("hidden"))) void ipmsm_free_cxx_runtime() { __gnu_cxx::__freeres(); }
