// RAII ownership of PETSc/SLEPc objects. A Handle destroys its object when it goes out of
// scope, so an error returned through PetscCall unwinds without leaks. Handles must be gone
// before SlepcFinalize(); main() scopes them accordingly.
#pragma once

#include <petscksp.h>
#include <petscviewer.h>
#include <slepceps.h>
#include <slepcpep.h>

#include <utility>

namespace squeal {

inline PetscErrorCode DestroyObject(Vec *v) { return VecDestroy(v); }
inline PetscErrorCode DestroyObject(Mat *m) { return MatDestroy(m); }
inline PetscErrorCode DestroyObject(KSP *k) { return KSPDestroy(k); }
inline PetscErrorCode DestroyObject(PEP *p) { return PEPDestroy(p); }
inline PetscErrorCode DestroyObject(EPS *e) { return EPSDestroy(e); }
inline PetscErrorCode DestroyObject(PetscViewer *v) { return PetscViewerDestroy(v); }
inline PetscErrorCode DestroyObject(VecScatter *s) { return VecScatterDestroy(s); }
inline PetscErrorCode DestroyObject(IS *s) { return ISDestroy(s); }

template <class T>
class Handle {
public:
  Handle() = default;
  explicit Handle(T obj) : obj_(obj) {}
  Handle(const Handle &) = delete;
  Handle &operator=(const Handle &) = delete;
  Handle(Handle &&o) noexcept : obj_(std::exchange(o.obj_, nullptr)) {}
  Handle &operator=(Handle &&o) noexcept {
    if (this != &o) {
      reset();
      obj_ = std::exchange(o.obj_, nullptr);
    }
    return *this;
  }
  ~Handle() { reset(); }

  // For creation calls: PetscCall(MatCreate(comm, A.out())). Releases what was held.
  T *out() {
    reset();
    return &obj_;
  }
  operator T() const { return obj_; }
  T get() const { return obj_; }
  explicit operator bool() const { return obj_ != nullptr; }
  void reset() {
    if (obj_) PetscCallVoid(DestroyObject(&obj_));
    obj_ = nullptr;
  }

private:
  T obj_ = nullptr;
};

using VecH    = Handle<Vec>;
using MatH    = Handle<Mat>;
using KSPH    = Handle<KSP>;
using PEPH    = Handle<PEP>;
using EPSH    = Handle<EPS>;
using ViewerH = Handle<PetscViewer>;

} // namespace squeal
