// googletest main: SLEPc (and so PETSc and MPI) initialised once for every test. Only rank 0
// prints googletest's report, so runs under mpiexec stay readable.
#include <gtest/gtest.h>
#include <slepcsys.h>

int main(int argc, char **argv)
{
  ::testing::InitGoogleTest(&argc, argv);
  PetscCall(SlepcInitialize(&argc, &argv, nullptr, nullptr));
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank != 0) {
    auto &listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  int result = RUN_ALL_TESTS();
  // Agree on the verdict so every rank exits the same way.
  MPI_Allreduce(MPI_IN_PLACE, &result, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  PetscCall(SlepcFinalize());
  return result;
}
