// The SUNDIALS objects of one CVODE integrator (RAII); private to plant/.
#pragma once

#include <cvode/cvode.h>
#include <cvode/cvode_ls.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

namespace ipmsm {

// The SUNDIALS objects, freed CVODE first (it refers to the solvers, the vector and the
// context), the context last.
struct CvodeHandles {
    SUNContext ctx = nullptr;
    N_Vector y = nullptr;
    N_Vector atol = nullptr;  // the absolute tolerances of y's components
    void* mem = nullptr;
    SUNNonlinearSolver nls = nullptr;
    SUNMatrix A = nullptr;
    SUNLinearSolver ls = nullptr;

    CvodeHandles() = default;
    CvodeHandles(const CvodeHandles&) = delete;
    CvodeHandles& operator=(const CvodeHandles&) = delete;
    ~CvodeHandles() {
        if (mem != nullptr) CVodeFree(&mem);
        if (ls != nullptr) SUNLinSolFree(ls);
        if (A != nullptr) SUNMatDestroy(A);
        if (nls != nullptr) SUNNonlinSolFree(nls);
        if (atol != nullptr) N_VDestroy(atol);
        if (y != nullptr) N_VDestroy(y);
        if (ctx != nullptr) SUNContext_Free(&ctx);
    }
};

}  // namespace ipmsm
