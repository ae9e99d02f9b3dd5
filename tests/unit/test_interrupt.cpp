// The pace of the signal polls in loops of steps (core/interrupt.h, InterruptPacer): every step on
// one rank; on several, about InterruptPacer::kSpacing seconds of the slowest rank's steps apart,
// the same polls on every rank (they are collective: a mismatch would hang here).
#include "squeal/core/interrupt.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

using namespace squeal;

namespace {

// Polls made by each rank, checked equal on all of them.
PetscInt AgreedPolls(const InterruptPacer &p, MPI_Comm comm)
{
  PetscInt lo = p.Polls(), hi = p.Polls();
  MPI_Allreduce(MPI_IN_PLACE, &lo, 1, MPIU_INT, MPI_MIN, comm);
  MPI_Allreduce(MPI_IN_PLACE, &hi, 1, MPIU_INT, MPI_MAX, comm);
  EXPECT_EQ(lo, hi) << "the ranks polled apart";
  return lo;
}

} // namespace

TEST(Interrupt, OnOneRankEveryStepIsAPoll)
{
  InterruptPacer p(PETSC_COMM_SELF, "the test's loop");
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(p.Step(), 0);
  EXPECT_EQ(p.Polls(), 1000);
}

// Steps of 10 ms on one rank (the other's are free, as a rank waiting for rank 0's step): the
// polls follow the slow rank, at most kSpacing / 10 ms = 5 steps apart, where a fixed count of 256
// steps (the code before) left 2.6 s between polls. Steps of nothing: the count grows fourfold a
// poll, a million steps in about ten polls.
TEST(Interrupt, OnSeveralRanksThePollsAreSpacedByTheSlowestRanksSteps)
{
  MPI_Comm    comm = PETSC_COMM_WORLD;
  PetscMPIInt size, rank;
  MPI_Comm_size(comm, &size);
  MPI_Comm_rank(comm, &rank);
  const int      slow_steps = 40;
  const double   step       = 0.010;
  const PetscInt most       = (PetscInt)(InterruptPacer::kSpacing / step + 0.5);
  {
    InterruptPacer p(comm, "the test's slow loop");
    for (int i = 0; i < slow_steps; ++i) {
      ASSERT_EQ(p.Step(), 0);
      if (rank == size - 1) std::this_thread::sleep_for(std::chrono::duration<double>(step));
    }
    const PetscInt polls = AgreedPolls(p, comm);
    if (size == 1) EXPECT_EQ(polls, slow_steps);
    else EXPECT_GE(polls, slow_steps / most) << "polls more than " << most << " steps of " << step << " s apart";
  }
  {
    const int      fast_steps = 1000000;
    InterruptPacer p(comm, "the test's fast loop");
    for (int i = 0; i < fast_steps; ++i) ASSERT_EQ(p.Step(), 0);
    const PetscInt polls = AgreedPolls(p, comm);
    if (size == 1) EXPECT_EQ(polls, fast_steps);
    else {
      EXPECT_GE(polls, 1);
      EXPECT_LE(polls, 1000) << "a collective poll nearly every step of nothing";
    }
  }
}
