// The results writer, read back with the HDF5 C API.
#include "squeal/io/h5.h"

#include <gtest/gtest.h>

#include <cstring>

using namespace squeal;

TEST(H5Writer, ArraysAttributesAndVecsReadBack)
{
  const std::string path = testing::TempDir() + "squeal_h5_test.h5";
  PetscMPIInt       rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    const double data[6] = {1.5, -2, 3, 4e-300, 5e300, 6};
    ASSERT_EQ(out.WriteArray("/a/b/table", {3, 2}, data), 0);
    ASSERT_EQ(out.WriteAttribute("/a/b/table", "units", "1/s"), 0);
    ASSERT_EQ(out.WriteAttribute("/a", "critical_mu", std::vector<PetscReal>{0.25, 0.5}), 0);
    ASSERT_EQ(out.WriteAttribute("/a", "count", (PetscInt)7), 0);
    Vec v;
    ASSERT_EQ(VecCreateMPI(PETSC_COMM_WORLD, PETSC_DECIDE, 5, &v), 0);
    ASSERT_EQ(PetscObjectSetName((PetscObject)v, "U"), 0);
    PetscInt lo, hi;
    ASSERT_EQ(VecGetOwnershipRange(v, &lo, &hi), 0);
    for (PetscInt i = lo; i < hi; ++i) ASSERT_EQ(VecSetValue(v, i, 10.0 * i, INSERT_VALUES), 0);
    ASSERT_EQ(VecAssemblyBegin(v), 0);
    ASSERT_EQ(VecAssemblyEnd(v), 0);
    ASSERT_EQ(out.WriteVec("/equilibrium", v), 0);
    ASSERT_EQ(VecDestroy(&v), 0);
  }
  MPI_Barrier(PETSC_COMM_WORLD);
  if (rank == 0) {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hid_t d = H5Dopen2(f, "/a/b/table", H5P_DEFAULT);
    const hid_t s = H5Dget_space(d);
    hsize_t     dims[2];
    ASSERT_EQ(H5Sget_simple_extent_ndims(s), 2);
    H5Sget_simple_extent_dims(s, dims, nullptr);
    EXPECT_EQ(dims[0], 3u);
    EXPECT_EQ(dims[1], 2u);
    double back[6];
    ASSERT_GE(H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, back), 0);
    EXPECT_EQ(back[0], 1.5);
    EXPECT_EQ(back[3], 4e-300);
    EXPECT_EQ(back[4], 5e300);
    const hid_t a = H5Aopen(d, "units", H5P_DEFAULT);
    const hid_t t = H5Aget_type(a);
    char        units[16] = {0};
    ASSERT_LT(H5Tget_size(t), sizeof(units));
    ASSERT_GE(H5Aread(a, t, units), 0);
    EXPECT_STREQ(units, "1/s");
    H5Tclose(t);
    H5Aclose(a);
    H5Sclose(s);
    H5Dclose(d);
    const hid_t g  = H5Oopen(f, "/a", H5P_DEFAULT);
    const hid_t ac = H5Aopen(g, "critical_mu", H5P_DEFAULT);
    double      mu[2];
    ASSERT_GE(H5Aread(ac, H5T_NATIVE_DOUBLE, mu), 0);
    EXPECT_EQ(mu[0], 0.25);
    EXPECT_EQ(mu[1], 0.5);
    H5Aclose(ac);
    H5Oclose(g);
    const hid_t du = H5Dopen2(f, "/equilibrium/U", H5P_DEFAULT);
    ASSERT_GE(du, 0);
    double u[5];
    ASSERT_GE(H5Dread(du, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, u), 0);
    for (int i = 0; i < 5; ++i) EXPECT_EQ(u[i], 10.0 * i);
    H5Dclose(du);
    H5Fclose(f);
  }
}

// An empty list attribute (a steady state interrupted before its spectrum has bases) is written as a
// zero-length attribute, not an HDF5 error that loses the analysis' other results.
TEST(H5Writer, AnEmptyListAttributeIsZeroLength)
{
  const std::string path = testing::TempDir() + "squeal_h5_empty_attr.h5";
  PetscMPIInt       rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    ASSERT_EQ(out.WriteAttribute("/steady_state", "bases", std::vector<PetscReal>{}), 0);
    ASSERT_EQ(out.WriteAttribute("/steady_state", "rms", 1.25), 0);
    ASSERT_EQ(out.Close(), 0);
  }
  MPI_Barrier(PETSC_COMM_WORLD);
  if (rank == 0) {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hid_t g = H5Oopen(f, "/steady_state", H5P_DEFAULT);
    ASSERT_GE(g, 0);
    const hid_t a = H5Aopen(g, "bases", H5P_DEFAULT);
    ASSERT_GE(a, 0);
    const hid_t s = H5Aget_space(a);
    EXPECT_EQ(H5Sget_simple_extent_npoints(s), 0);
    H5Sclose(s);
    H5Aclose(a);
    double      rms = 0;
    const hid_t ar  = H5Aopen(g, "rms", H5P_DEFAULT);
    ASSERT_GE(H5Aread(ar, H5T_NATIVE_DOUBLE, &rms), 0);
    EXPECT_EQ(rms, 1.25);
    H5Aclose(ar);
    H5Oclose(g);
    H5Fclose(f);
  }
}
