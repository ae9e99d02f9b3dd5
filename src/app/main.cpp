#include "squeal/app/app.h"
#include "squeal/core/errors.h"
#include "squeal/core/interrupt.h"

#include <slepcsys.h>

int main(int argc, char **argv)
{
  PetscCall(SlepcInitialize(&argc, &argv, nullptr, squeal::kHelp));
  PetscErrorCode ierr = squeal::PushErrorHandler();
  if (!ierr) ierr = squeal::InstallInterruptHandlers();
  if (!ierr) {
    ierr = squeal::RunApp(argc, argv);
    PetscCall(PetscPopErrorHandler());
  }
  PetscCall(SlepcFinalize());
  return ierr ? 1 : 0;
}
