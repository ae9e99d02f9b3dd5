#include "squeal/steady/steady_state.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numeric>

namespace squeal {

namespace steady {

namespace {

using cd = std::complex<double>;

// In place, a.size() a power of 2.
void Radix2(std::vector<cd> &a)
{
  const size_t n = a.size();
  for (size_t i = 1, j = 0; i < n; ++i) {
    size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(a[i], a[j]);
  }
  for (size_t len = 2; len <= n; len <<= 1) {
    for (size_t i = 0; i < n; i += len)
      for (size_t k = 0; k < len / 2; ++k) {
        // The twiddle from its own angle, not by repeated products: no accumulated rounding.
        const cd w = std::polar(1.0, -2 * M_PI * (double)k / (double)len);
        const cd u = a[i + k], v = a[i + k + len / 2] * w;
        a[i + k] = u + v, a[i + k + len / 2] = u - v;
      }
  }
}

size_t NextPow2(size_t n)
{
  size_t m = 1;
  while (m < n) m <<= 1;
  return m;
}

// The full DFT of a (any length): radix 2, else Bluestein, X_k = w_k sum_j (a_j w_j) conj(w_{k-j}),
// w_j = exp(-i pi j^2 / n), the convolution by power-of-2 FFTs.
std::vector<cd> DFT(const std::vector<cd> &a)
{
  const size_t n = a.size();
  if (n <= 1) return a;
  if ((n & (n - 1)) == 0) {
    std::vector<cd> b = a;
    Radix2(b);
    return b;
  }
  std::vector<cd> w(n);
  for (size_t j = 0; j < n; ++j) {
    const uint64_t q = ((uint64_t)j * j) % (2 * (uint64_t)n); // exact: the angle stays small
    w[j]             = std::polar(1.0, -M_PI * (double)q / (double)n);
  }
  const size_t    m = NextPow2(2 * n - 1);
  std::vector<cd> A(m, 0.0), B(m, 0.0);
  for (size_t j = 0; j < n; ++j) A[j] = a[j] * w[j];
  B[0] = 1.0;
  for (size_t j = 1; j < n; ++j) B[j] = B[m - j] = std::conj(w[j]);
  Radix2(A);
  Radix2(B);
  for (size_t k = 0; k < m; ++k) A[k] *= B[k];
  // Inverse by conjugation.
  for (cd &z : A) z = std::conj(z);
  Radix2(A);
  std::vector<cd> X(n);
  for (size_t k = 0; k < n; ++k) X[k] = std::conj(A[k]) / (double)m * w[k];
  return X;
}

std::vector<double> Hann(size_t L) // numpy.hanning: symmetric
{
  std::vector<double> w(L, 1.0);
  if (L > 1)
    for (size_t i = 0; i < L; ++i) w[i] = 0.5 - 0.5 * std::cos(2 * M_PI * (double)i / (double)(L - 1));
  return w;
}

double Mean(const double *x, size_t n)
{
  return n ? std::accumulate(x, x + n, 0.0) / (double)n : 0.0;
}

double Median(std::vector<double> v)
{
  if (v.empty()) return 0;
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  if (v.size() % 2) return v[h];
  const double hi = v[h];
  return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + h));
}

// Each rough frequency refined on the whole record's Hann spectrum, 4x zero-padded, within +-width.
std::vector<double> RefinePeaks(const std::vector<double> &x, double dt, const std::vector<double> &f0, double width)
{
  const size_t        n = x.size(), nfft = 4 * n;
  const double        mu = Mean(x.data(), n);
  std::vector<double> w = Hann(n), y(n);
  for (size_t i = 0; i < n; ++i) y[i] = (x[i] - mu) * w[i];
  const std::vector<cd> X = RealFFT(y, nfft);
  const double          df = 1.0 / (nfft * dt);
  std::vector<double>   out;
  for (double g : f0) {
    // numpy.searchsorted (left) on k df.
    auto   idx = [&](double f) { return (size_t)std::max(0.0, std::min((double)X.size(), std::ceil(f / df))); };
    size_t lo = idx(g - width), hi = std::min(idx(g + width), X.size() - 1), i = lo;
    for (size_t k = lo; k <= hi; ++k)
      if (std::abs(X[k]) > std::abs(X[i])) i = k;
    double fi = (double)i;
    if (i > 0 && i + 1 < X.size()) {
      const double a = std::log(std::abs(X[i - 1]) + 1e-300), b = std::log(std::abs(X[i]) + 1e-300),
                   c = std::log(std::abs(X[i + 1]) + 1e-300);
      fi += 0.5 * (a - c) / (a - 2 * b + c);
    }
    out.push_back(fi * df);
  }
  return out;
}

} // namespace

std::vector<std::complex<double>> RealFFT(const std::vector<double> &x, size_t nfft)
{
  std::vector<cd> a(nfft, 0.0);
  for (size_t i = 0; i < x.size() && i < nfft; ++i) a[i] = x[i];
  std::vector<cd> X = DFT(a);
  X.resize(nfft / 2 + 1);
  return X;
}

double StudentT975(long dof)
{
  // Exact to 3 decimals for 1..30; beyond, the entry at the largest tabulated dof below (larger t).
  static const double t[] = {12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
                             2.120,  2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042};
  if (dof < 1) return INFINITY;
  if (dof <= 30) return t[dof - 1];
  if (dof < 40) return 2.042;
  if (dof < 60) return 2.021;
  if (dof < 120) return 2.000;
  return 1.980;
}

size_t MserCut(const std::vector<double> &x, size_t batch)
{
  const size_t n = batch ? x.size() / batch : 0;
  if (n < 4) return 0;
  const double        mu = Mean(x.data(), x.size());
  std::vector<double> p(n);
  for (size_t j = 0; j < n; ++j) {
    double s = 0;
    for (size_t i = j * batch; i < (j + 1) * batch; ++i) s += (x[i] - mu) * (x[i] - mu);
    p[j] = s / (double)batch;
  }
  double best = INFINITY;
  size_t cut  = 0;
  for (size_t d = 0; d <= n / 2; ++d) {
    const size_t m = n - d;
    if (m < 2) break;
    const double pm = Mean(p.data() + d, m);
    double       v  = 0;
    for (size_t j = d; j < n; ++j) v += (p[j] - pm) * (p[j] - pm);
    const double s = v / (double)m / (double)(m - 1);
    if (s < best) best = s, cut = d;
  }
  return cut * batch;
}

size_t DominantPeriodRecords(const std::vector<double> &x)
{
  const size_t        n  = x.size();
  const double        mu = Mean(x.data(), n);
  std::vector<double> w = Hann(n), y(n);
  for (size_t i = 0; i < n; ++i) y[i] = (x[i] - mu) * w[i];
  const std::vector<cd> X = RealFFT(y, n);
  size_t                k = 1;
  for (size_t i = 1; i < X.size(); ++i)
    if (std::abs(X[i]) > std::abs(X[k])) k = i;
  return std::max<size_t>(5, (size_t)std::llround((double)n / (double)k));
}

Levels BatchLevels(const std::vector<double> &x, long batches)
{
  Levels       L;
  const size_t n = x.size();
  if (n < 4) return L;
  L.mean = Mean(x.data(), n);
  double ss = 0;
  for (double v : x) ss += (v - L.mean) * (v - L.mean), L.peak = std::max(L.peak, std::abs(v - L.mean));
  L.rms           = std::sqrt(ss / (double)n);
  const size_t nb = std::min<size_t>((size_t)std::max(2L, batches), n / 2), len = n / nb;
  std::vector<double> b(nb, 0.0);
  for (size_t k = 0; k < nb; ++k) {
    for (size_t i = k * len; i < (k + 1) * len; ++i) b[k] += (x[i] - L.mean) * (x[i] - L.mean);
    b[k] /= (double)len;
  }
  const double bm = Mean(b.data(), nb);
  double       v  = 0;
  for (double q : b) v += (q - bm) * (q - bm);
  const double half = StudentT975((long)nb - 1) * std::sqrt(v / (double)(nb - 1)) / std::sqrt((double)nb);
  L.rms_lo          = std::sqrt(std::max(bm - half, 0.0));
  L.rms_hi          = std::sqrt(bm + half);
  L.rel_halfwidth   = L.rms > 0 ? (L.rms_hi - L.rms_lo) / (2 * L.rms) : 0.0;
  double sxy = 0, sxx = 0;
  for (size_t k = 0; k < nb; ++k) {
    const double c = (double)k - 0.5 * (double)(nb - 1);
    sxy += c * (b[k] - bm), sxx += c * c;
  }
  L.drift = bm > 0 ? std::abs(sxy / sxx) * (double)nb / bm / 2 : 0.0;
  return L;
}

void Welch(const std::vector<double> &x, double dt, int segments, std::vector<double> &freq, std::vector<double> &psd)
{
  const size_t        n = x.size(), L = std::max<size_t>(16, 2 * n / (size_t)(segments + 1)), step = L / 2;
  const std::vector<double> w = Hann(L);
  double                    ww = 0;
  for (double q : w) ww += q * q;
  const double scale = dt / ww;
  psd.assign(L / 2 + 1, 0.0);
  freq.resize(L / 2 + 1);
  for (size_t k = 0; k < freq.size(); ++k) freq[k] = (double)k / ((double)L * dt);
  size_t              count = 0;
  std::vector<double> seg(L);
  for (size_t s = 0; s + L <= n; s += step, ++count) {
    const double mu = Mean(x.data() + s, L);
    for (size_t i = 0; i < L; ++i) seg[i] = (x[s + i] - mu) * w[i];
    const std::vector<cd> X = RealFFT(seg, L);
    for (size_t k = 0; k < psd.size(); ++k) psd[k] += std::norm(X[k]);
  }
  for (size_t k = 0; k < psd.size(); ++k) psd[k] *= count ? scale / (double)count : 0.0;
  // One-sided: every bin but DC and (for even L) Nyquist counts twice, as numpy's psd[1:-1] *= 2.
  for (size_t k = 1; k + 1 < psd.size(); ++k) psd[k] *= 2;
}

std::vector<size_t> FindLines(const std::vector<double> &psd, double floor_factor, size_t max_lines, double *floor)
{
  const double f = psd.size() > 1 ? Median(std::vector<double>(psd.begin() + 1, psd.end())) : 0.0;
  if (floor) *floor = f;
  std::vector<size_t> peaks;
  for (size_t i = 1; i + 1 < psd.size(); ++i)
    if (psd[i] >= psd[i - 1] && psd[i] > psd[i + 1] && psd[i] > floor_factor * f) peaks.push_back(i);
  std::stable_sort(peaks.begin(), peaks.end(), [&](size_t a, size_t b) { return psd[a] > psd[b]; });
  if (peaks.size() > max_lines) peaks.resize(max_lines);
  return peaks;
}

void FitLines(const std::vector<double> &x, double dt, const std::vector<double> &f0, std::vector<double> &f, std::vector<double> &amp)
{
  const Eigen::Index n = (Eigen::Index)x.size(), k = (Eigen::Index)f0.size();
  f.clear(), amp.clear();
  if (k == 0 || n < 4) return;
  const double    width = 1.5 / (dt * (double)std::max<size_t>(16, 2 * x.size() / 9)); // 1.5 Welch bins
  Eigen::VectorXd fr    = Eigen::Map<const Eigen::VectorXd>(RefinePeaks(x, dt, f0, width).data(), k);
  const double    mu    = Mean(x.data(), x.size());
  Eigen::VectorXd y(n), tt(n);
  for (Eigen::Index i = 0; i < n; ++i) y[i] = x[i] - mu, tt[i] = (double)i * dt;
  Eigen::MatrixXd A(n, 2 * k), J(n, k);
  Eigen::VectorXd ab;
  auto            basis = [&]() {
    for (Eigen::Index j = 0; j < k; ++j)
      for (Eigen::Index i = 0; i < n; ++i) {
        const double ph = 2 * M_PI * fr[j] * tt[i];
        A(i, j) = std::cos(ph), A(i, k + j) = std::sin(ph);
      }
    ab = A.colPivHouseholderQr().solve(y);
  };
  for (int it = 0; it < 8; ++it) {
    basis();
    const Eigen::VectorXd r = y - A * ab;
    for (Eigen::Index j = 0; j < k; ++j)
      J.col(j) = (2 * M_PI * tt.array() * (-ab[j] * A.col(k + j).array() + ab[k + j] * A.col(j).array())).matrix();
    const Eigen::VectorXd df = J.colPivHouseholderQr().solve(r);
    fr += df;
    if ((df.array().abs() <= 1e-13 * fr.array().abs()).all()) break;
  }
  basis();
  for (Eigen::Index j = 0; j < k; ++j) f.push_back(fr[j]), amp.push_back(std::hypot(ab[j], ab[k + j]));
}

namespace {

// A line is named k f1 or m f1 + n f2 within 3 resolutions of the whole record.
double NameTolerance(double df_res, double g) { return std::max(3 * df_res, 1e-9 * g); }

// Above this chance of naming a line anywhere in the band, the names prove nothing.
constexpr double kMaxNamingChance = 0.25;

// The share of (0, F] (F: the highest line) within the tolerance of a name: 2 tol / f1 for the
// harmonics of one base; with two, the names m f1 + n f2 (|m|, |n| <= 4) in (0, F] times 2 tol / F.
double NamingChance(const std::vector<double> &f, const std::vector<double> &bases, double df_res)
{
  const double F = *std::max_element(f.begin(), f.end()), tol = NameTolerance(df_res, 0);
  if (bases.size() == 1) return std::min(1.0, 2 * tol / bases[0]);
  int names = 0;
  for (int m = -4; m <= 4; ++m)
    for (int n = -4; n <= 4; ++n) {
      const double g = m * bases[0] + n * bases[1];
      names += g > 0 && g <= F + tol;
    }
  return std::min(1.0, names * 2 * tol / F);
}

} // namespace

Classification Classify(const std::vector<double> &f, const std::vector<double> &amp, double power_in_lines, double total_power,
                        double df_res)
{
  Classification c;
  char           b[256];
  if (f.empty() || power_in_lines < 0.5 * total_power) {
    const double share = total_power > 0 ? power_in_lines / total_power : 0.0;
    std::snprintf(b, sizeof b, "lines carry %.0f%% of the power (< 50 %%)", 100 * share);
    c.verdict = "broadband", c.evidence = b;
    return c;
  }
  std::vector<size_t> order(f.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t q) { return amp[a] > amp[q]; });
  // The base is the strongest line, or the lowest line of which it is a harmonic: a wave whose
  // second harmonic is the stronger (the small pad at V = 10 m/s, DOF 120: 17 325 Hz over 8 662 Hz)
  // is periodic in the lower one, not a second base at half the first.
  double f1 = f[order[0]];
  for (size_t i : order) {
    const double k = std::nearbyint(f[order[0]] / f[i]);
    if (f[i] < f1 && k >= 2 && std::abs(f[order[0]] - k * f[i]) <= std::max(3 * df_res, 1e-9 * f[order[0]])) f1 = f[i];
  }
  c.bases = {f1};
  auto name_of = [&](double g, std::string &name) {
    const double tol = NameTolerance(df_res, g);
    if (c.bases.size() == 1) {
      const double k = std::nearbyint(g / c.bases[0]);
      if (k >= 1 && std::abs(g - k * c.bases[0]) <= tol) {
        std::snprintf(b, sizeof b, "%.0f f1", k);
        name = b;
        return true;
      }
      return false;
    }
    int best = -1;
    for (int m = -4; m <= 4; ++m)
      for (int n = -4; n <= 4; ++n) {
        if (m == 0 && n == 0) continue;
        if (std::abs(g - (m * c.bases[0] + n * c.bases[1])) <= tol && (best < 0 || std::abs(m) + std::abs(n) < best)) {
          best = std::abs(m) + std::abs(n);
          std::snprintf(b, sizeof b, "%d f1 %c %d f2", m, n >= 0 ? '+' : '-', std::abs(n));
          name = b;
        }
      }
    return best >= 0;
  };
  c.names.assign(f.size(), "unexplained");
  for (size_t i : order) {
    std::string nm;
    bool        ok = name_of(f[i], nm);
    if (!ok && c.bases.size() == 1) {
      c.bases.push_back(f[i]);
      ok = name_of(f[i], nm);
    }
    if (ok) c.names[i] = nm;
  }
  // Names given by chance: a line anywhere in the band would be named, within the tolerance, with
  // this probability. A short record's tolerance can cover most of the band (the brake, 50 periods:
  // +-1164 Hz, and 16 573 Hz was called "2 f1" of 7 741 Hz): a periodic or quasi-periodic verdict
  // is then "unresolved".
  // Unexplained lines are evidence whatever the tolerance (a wider one could only name more).
  const double chance = NamingChance(f, c.bases, df_res);
  if (c.bases.size() == 1) {
    std::snprintf(b, sizeof b, "every line a harmonic of f1 = %.6g Hz", c.bases[0]);
    c.verdict = "periodic", c.evidence = b;
  } else {
    const long unexplained = std::count(c.names.begin(), c.names.end(), std::string("unexplained"));
    std::snprintf(b, sizeof b, "two bases f1 = %.6g Hz, f2 = %.6g Hz (ratio %.6f), %ld line(s) unexplained", c.bases[0], c.bases[1],
                  c.bases[1] / c.bases[0], unexplained);
    c.verdict  = unexplained == 0 ? "quasi-periodic" : "broadband";
    c.evidence = b;
  }
  if (c.verdict != "broadband" && f.size() > c.bases.size() && chance > kMaxNamingChance) {
    std::snprintf(b, sizeof b, "; but at the record's resolution (+-%.3g Hz) %.0f %% of the band would be named by chance: run on (-steady_max_periods)",
                  NameTolerance(df_res, 0), 100 * chance);
    c.verdict = "unresolved", c.evidence += b;
  }
  return c;
}

Analysis Analyse(const std::vector<double> &x, double dt, long batches)
{
  Analysis a;
  // MSER on the power of whole periods: within a period the power swings with the phase.
  a.cut = MserCut(x, DominantPeriodRecords(x));
  const std::vector<double> xs(x.begin() + (long)a.cut, x.end());
  a.levels = BatchLevels(xs, batches);
  Welch(xs, dt, 8, a.freq, a.psd);
  const std::vector<size_t> peaks = FindLines(a.psd, 100.0, 8, nullptr);
  const double              df    = a.freq.size() > 1 ? a.freq[1] - a.freq[0] : 0.0;
  std::vector<double>       f0;
  for (size_t i : peaks) f0.push_back(a.freq[i]);
  FitLines(xs, dt, f0, a.lines, a.amplitudes);
  const double total = std::accumulate(a.psd.begin(), a.psd.end(), 0.0) * df;
  double       in_lines = 0;
  for (double q : a.amplitudes) in_lines += q * q / 2;
  // Lines are named to within 3 resolutions of the whole record, 1 / (n dt), not of the Welch
  // segments: those are 4.5x coarser, and on the small pad at V = 10 m/s their 3 bins (505 Hz)
  // called 12 958 Hz the third harmonic of 4 203 Hz (12 609 Hz).
  a.cls = Classify(a.lines, a.amplitudes, in_lines, total, xs.empty() ? df : 1.0 / ((double)xs.size() * dt));
  return a;
}

bool ModalProjection::SetUp(const std::vector<std::vector<double>> &re, const std::vector<std::vector<double>> &im, size_t every,
                            std::string *why)
{
  *this    = ModalProjection{};
  every_   = std::max<size_t>(1, every);
  N_       = re.empty() ? 0 : re[0].size();
  size_t m = 0;
  for (size_t j = 0; j < re.size(); ++j) m += im[j].empty() ? 1 : 2;
  if (re.empty() || m > N_) {
    if (why) *why = re.empty() ? "no mode to project on" : "more mode columns than DOFs";
    N_ = 0;
    return false;
  }
  Eigen::MatrixXd B(N_, m);
  for (size_t j = 0, c = 0; j < re.size(); ++j) {
    cols_.push_back({c});
    B.col(c++) = Eigen::Map<const Eigen::VectorXd>(re[j].data(), (Eigen::Index)N_);
    if (!im[j].empty()) {
      cols_.back().push_back(c);
      B.col(c++) = Eigen::Map<const Eigen::VectorXd>(im[j].data(), (Eigen::Index)N_);
    }
  }
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(B);
  Q_ = qr.householderQ() * Eigen::MatrixXd::Identity((Eigen::Index)N_, (Eigen::Index)m);
  R_ = qr.matrixQR().topRows((Eigen::Index)m).triangularView<Eigen::Upper>();
  const Eigen::VectorXd d = R_.diagonal().cwiseAbs();
  // The ratio of R's extreme diagonal entries bounds B's condition number from below; the
  // singular values give it.
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(R_);
  const Eigen::VectorXd             sv = svd.singularValues();
  const double                      cond = sv(sv.size() - 1) > 0 ? sv(0) / sv(sv.size() - 1) : INFINITY;
  if (!(d.minCoeff() > 0) || !(cond < 1e10)) {
    if (why) {
      char b[160];
      std::snprintf(b, sizeof b, "the unstable modes' shapes are (nearly) linearly dependent (condition number %.3g): no modal coordinates", cond);
      *why = b;
    }
    N_ = 0, cols_.clear();
    return false;
  }
  cond_ = cond;
  return true;
}

void ModalProjection::Add(const double *u, size_t n, size_t first)
{
  if (!N_) return;
  const Eigen::Index N = (Eigen::Index)N_;
  for (size_t i = first; i < n; ++i) {
    Eigen::Map<const Eigen::VectorXd> ui(u + i * N_, N);
    if (e_.empty()) ref_ = ui, sum_ = Eigen::VectorXd::Zero(N);
    if (e_.size() % every_ == 0) checkpoints_.push_back(sum_);
    const Eigen::VectorXd y = ui - ref_;
    z_.push_back(Q_.transpose() * y);
    e_.push_back(y.squaredNorm());
    sum_ += y;
  }
}

ModalProjection::Result ModalProjection::Analyse(size_t cut) const
{
  Result       r;
  const size_t n = e_.size();
  if (!N_ || n < 2) return r;
  r.cond = cond_;
  // The window: from a checkpoint (its running sum known), the first at or after the cut.
  size_t c = (cut + every_ - 1) / every_;
  while (c > 0 && (c >= checkpoints_.size() || n - c * every_ < 2)) --c;
  r.from    = c * every_;
  r.records = n - r.from;
  const double          m    = (double)r.records;
  const Eigen::VectorXd ubar = (sum_ - checkpoints_[c]) / m;
  double                ee   = 0;
  Eigen::VectorXd       zbar = Eigen::VectorXd::Zero(Q_.cols());
  for (size_t i = r.from; i < n; ++i) ee += e_[i], zbar += z_[i];
  zbar /= m;
  r.variance = std::max(0.0, ee / m - ubar.squaredNorm());
  const size_t k = cols_.size(), ncol = (size_t)Q_.cols();
  r.q            = Eigen::MatrixXd::Zero((Eigen::Index)r.records, (Eigen::Index)(2 * k));
  Eigen::MatrixXd coef((Eigen::Index)ncol, (Eigen::Index)r.records);
  double          fitted = 0;
  for (size_t i = r.from; i < n; ++i) {
    const Eigen::VectorXd dz = z_[i] - zbar;
    fitted += dz.squaredNorm();
    coef.col((Eigen::Index)(i - r.from)) = R_.triangularView<Eigen::Upper>().solve(dz);
  }
  r.explained = r.variance > 0 ? std::min(1.0, fitted / m / r.variance) : 0.0;
  r.rms.assign(k, 0.0), r.share.assign(k, 0.0);
  for (size_t j = 0; j < k; ++j) {
    const std::vector<size_t> &cj = cols_[j];
    // |B_j q_j|^2 = q_j^T (R_j^T R_j) q_j with R_j the columns of R for mode j (B = Q R, Q^T Q = I).
    Eigen::MatrixXd Rj(R_.rows(), (Eigen::Index)cj.size());
    for (size_t l = 0; l < cj.size(); ++l) Rj.col((Eigen::Index)l) = R_.col((Eigen::Index)cj[l]);
    const Eigen::MatrixXd G = Rj.transpose() * Rj;
    double                s2 = 0, p2 = 0;
    for (Eigen::Index i = 0; i < (Eigen::Index)r.records; ++i) {
      Eigen::VectorXd qj((Eigen::Index)cj.size());
      for (size_t l = 0; l < cj.size(); ++l) qj((Eigen::Index)l) = coef((Eigen::Index)cj[l], i);
      r.q(i, (Eigen::Index)(2 * j)) = qj(0);
      if (cj.size() > 1) r.q(i, (Eigen::Index)(2 * j + 1)) = qj(1);
      s2 += qj.squaredNorm(), p2 += qj.dot(G * qj);
    }
    r.rms[j]   = std::sqrt(s2 / m);
    r.share[j] = r.variance > 0 ? p2 / m / r.variance : 0.0;
  }
  return r;
}

} // namespace steady

SteadyState::~SteadyState()
{
  if (monitor_) PetscCallAbort(comm_, PetscViewerDestroy(&monitor_));
}

PetscErrorCode SteadyState::SetFromOptions()
{
  OptionChecks checks;
  PetscBool    mon = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "steady_", "Statistical steady state (levels and spectrum of a transient without a periodic orbit)", "SteadyState");
  SquealOptionsReal("-rtol", "Converged: the 95 % interval of the RMS has a half-width, and the RMS a drift over the record, below this (relative; signal DOF and total normal reaction)",
                    "SteadyState", &rtol, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-batches", "Batches for the batch-means interval (Student t)", "SteadyState", batches, &batches, nullptr));
  SquealOptionsReal("-chunk_periods", "The transient runs on in chunks of this many periods of the starting mode until converged",
                    "SteadyState", &chunk_periods, Range::Positive(), checks);
  SquealOptionsReal("-max_periods", "Budget: at most this many periods of the starting mode in all", "SteadyState", &max_periods,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-dof", "DOF whose levels and spectrum are computed (-1: the one the transient's cycle summary reads, "
                                    "the DOF that moves most)",
                            "SteadyState", dof, &dof, nullptr));
  PetscCall(PetscOptionsBool("-from_mode",
                             "-analyses auto's statistical route starts from the mode (as the transient; false: from the pre-periods' end state)",
                             "SteadyState", from_mode, &from_mode, nullptr));
  PetscCall(PetscOptionsName("-monitor", "After each chunk: the start-up cut, levels, lines and verdict so far ([viewer], default stdout)",
                             "SteadyState", &mon));
  PetscCall(PetscOptionsName("-view", "The result after the run ([viewer])", "SteadyState", nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(batches >= 2, comm_, kErrInput, "option -steady_batches = %" PetscInt_FMT ": expected >= 2", batches);
  PetscCheck(dof >= -1, comm_, kErrInput, "option -steady_dof = %" PetscInt_FMT ": expected a DOF index >= 0 (or -1)", dof);
  PetscCheck(max_periods >= chunk_periods, comm_, kErrInput,
             "option -steady_max_periods = %g is below -steady_chunk_periods = %g: expected at least one chunk", (double)max_periods,
             (double)chunk_periods);
  if (monitor_) PetscCall(PetscViewerDestroy(&monitor_));
  if (mon) {
    PetscBool flg;
    PetscCall(PetscOptionsGetViewer(comm_, nullptr, "steady_", "-monitor", &monitor_, &monitor_format_, &flg));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::Analyse(SteadyStateResult &res) const
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  int conv = 0;
  if (rank == 0 && res.t.size() >= 2) {
    PetscCallCXX(res.signal = steady::Analyse(res.x, res.t[1] - res.t[0], batches));
    if (!res.rn.empty()) {
      const std::vector<double> r(res.rn.begin() + (long)res.signal.cut, res.rn.end());
      res.normal = steady::BatchLevels(r, batches);
    }
    if (res.projection.Modes()) res.modal = res.projection.Analyse(res.signal.cut);
    const steady::Levels &L = res.signal.levels, &R = res.normal;
    conv = L.rms > 0 && L.rel_halfwidth < rtol && L.drift < rtol && (res.rn.empty() || (R.rel_halfwidth < rtol && R.drift < rtol));
  }
  PetscCallMPI(MPI_Bcast(&conv, 1, MPI_INT, 0, comm_));
  res.converged = conv;
  PetscFunctionReturn(0);
}

namespace {
// Above this many DOFs the statistical steady state takes kFeStepsPerPeriod steps per period.
constexpr PetscInt  kDenseStepsMaxDofs = 200;
constexpr PetscReal kFeStepsPerPeriod  = 200;
} // namespace

PetscErrorCode SteadyState::Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                                TransientAnalysis &transient, const std::vector<PetscReal> &u0, const std::vector<PetscReal> &du0,
                                const std::string &start, SteadyStateResult &res)
{
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  PetscMPIInt    rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCheck(dof < N, comm_, kErrInput, "option -steady_dof = %" PetscInt_FMT ": the model has %" PetscInt_FMT " DOFs", dof, N);
  const auto t0 = std::chrono::steady_clock::now();
  res           = SteadyStateResult{};
  res.start     = start;
  // The transient's settings, put back on the way out: each chunk starts where the last ended.
  struct Restore {
    TransientAnalysis     &tr;
    std::vector<PetscReal> u0, du0;
    PetscReal              periods, t_final, h, steps;
    ~Restore() { tr.u0 = u0, tr.du0 = du0, tr.periods = periods, tr.t_final = t_final, tr.h = h, tr.steps_per_period = steps; }
  } restore{transient, transient.u0, transient.du0, transient.periods, transient.t_final, transient.h, transient.steps_per_period};
  if (!u0.empty()) transient.u0 = u0, transient.du0 = du0;
  // Steps per period from the model unless given: the statistics of an FE model need its levels and
  // lines, not the phase of one period to 1e-6, and at the transient's 1000 a 50-period chunk of
  // the 2625-DOF pad (807 DOFs) took 10.5 min, of the brake (1267 DOFs) 15 min, loaded. 200, as
  // shooting above 99 DOFs: a period error (2 pi / 200)^2 / 12 = 8e-5.
  if (!transient.steps_given && N > kDenseStepsMaxDofs && transient.steps_per_period > kFeStepsPerPeriod) {
    transient.steps_per_period = kFeStepsPerPeriod;
    PetscCall(PetscPrintf(comm_, "steady state: %d steps per period for N = %" PetscInt_FMT " DOFs (-transient_steps_per_period: chosen from the model unless given)\n",
                          (int)kFeStepsPerPeriod, N));
  }
  // The unstable modes' shapes on rank 0, for the modal projection of the records.
  std::vector<std::vector<double>> modes_re, modes_im;
  for (PetscInt m : stab.unstable) {
    const Mode &md = stab.modes[(size_t)m];
    if (!md.phi_re) {
      res.modal_note = "the stability analysis kept no mode shapes";
      modes_re.clear(), modes_im.clear(), res.mode_index.clear(), res.mode_frequency.clear(), res.mode_growth.clear();
      break;
    }
    std::vector<PetscReal> re, im;
    PetscCall(GatherVector(md.phi_re, false, re));
    if (md.Oscillatory() && md.phi_im) PetscCall(GatherVector(md.phi_im, false, im));
    modes_re.push_back(re), modes_im.push_back(im);
    res.mode_index.push_back(m), res.mode_frequency.push_back(md.Frequency()), res.mode_growth.push_back(md.sigma);
  }
  if (stab.unstable.empty()) res.modal_note = "no unstable mode in the band";
  if (rank != 0) modes_re.clear(), modes_im.clear();
  // Chunks of a whole number of records: the records of successive chunks lie on one grid.
  const PetscInt keep = transient.keep_every;
  PetscInt       chunk_steps = 0, max_chunks = 0;
  PetscReal      h = 0, elapsed = 0;
  for (PetscInt k = 0; !res.converged; ++k) {
    TransientResult tr;
    if (k == 0) {
      transient.periods = chunk_periods, transient.t_final = 0;
    } else {
      transient.h = h, transient.t_final = chunk_steps * h;
    }
    PetscCall(transient.Run(model, eq, stab, ti, tr));
    // Stopped by a signal (the transient leaves on nothing else without an error): the records so
    // far, this chunk's too, are analysed, and complete stays false.
    const bool         stopped = !tr.complete;
    unsigned long long have    = rank == 0 ? (unsigned long long)tr.t.size() : 0;
    PetscCallMPI(MPI_Bcast(&have, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_));
    if (stopped) {
      char b[256];
      std::snprintf(b, sizeof b, "interrupted by %s during chunk %" PetscInt_FMT " after %" PetscInt_FMT " of its steps%s",
                    InterruptSignal() ? InterruptSignalName() : "a signal", k + 1, tr.steps,
                    have < 2 || (k == 0 && have < 4) ? ", before enough records for the statistics" : "");
      res.interrupted = b;
      if (have < 2 || (k == 0 && have < 4)) break;
    }
    if (k == 0) {
      res.T_ref = tr.T_ref;
      h         = tr.h;
      PetscCheck(stopped || tr.keep_every == keep, comm_, kErrInput,
                 "steady state: the transient raised -transient_keep_every from %" PetscInt_FMT " to %" PetscInt_FMT
                 " for its memory budget; the chunks need one record grid: lower -steady_chunk_periods or set -transient_keep_every %" PetscInt_FMT,
                 keep, tr.keep_every, tr.keep_every);
      // Later chunks: a whole number of records, about chunk_periods each.
      chunk_steps = std::max<PetscInt>(keep, (PetscInt)std::llround(chunk_periods * tr.T_ref / h / keep) * keep);
      max_chunks  = 1 + (PetscInt)std::ceil((max_periods - chunk_periods) * tr.T_ref / (chunk_steps * h) - 1e-9);
      if (rank == 0) res.dof = dof >= 0 ? dof : std::max<PetscInt>(0, tr.summary.signal_dof);
      PetscCallMPI(MPI_Bcast(&res.dof, 1, MPIU_INT, 0, comm_));
      // Checkpoints of the modal sums about once per period of the starting mode, at most ~512 in
      // the budget: the modal window starts within a period of the start-up cut.
      if (rank == 0 && !modes_re.empty()) {
        const size_t per_period = std::max<size_t>(1, (size_t)std::llround(tr.T_ref / (h * keep)));
        const size_t every      = per_period * std::max<size_t>(1, (size_t)std::ceil(max_periods / 512.0));
        (void)res.projection.SetUp(modes_re, modes_im, every, &res.modal_note); // false: the note says why
      }
    }
    // Rank 0's records, appended (a later chunk's first record is the last one's end state).
    std::vector<PetscReal> endU(N), endV(N);
    if (rank == 0) {
      const size_t nr = tr.t.size();
      PetscCheck(nr >= 2 && (k == 0 || stopped || (tr.steps % keep) == 0), PETSC_COMM_SELF, PETSC_ERR_PLIB, "steady state: chunk %" PetscInt_FMT " off the record grid",
                 k);
      for (size_t i = k == 0 ? 0 : 1; i < nr; ++i) {
        res.t.push_back(elapsed + tr.t[i]);
        res.x.push_back(tr.U[i * N + res.dof]);
        if (nc > 0) {
          PetscReal s = 0;
          for (PetscInt c = 0; c < nc; ++c) s += tr.R[(i * nc + c) * 3 + 2];
          res.rn.push_back(s);
        }
      }
      std::copy(tr.U.end() - N, tr.U.end(), endU.begin());
      std::copy(tr.V.end() - N, tr.V.end(), endV.begin());
    }
    // The first chunk may end off the grid (its step count from -steady_chunk_periods): its tail
    // record is dropped from the statistics, and the next chunks start from it all the same. (A
    // stopped chunk's records are all on the grid: the transient keeps the end state only at its
    // last step.)
    const bool off_grid = !stopped && k == 0 && tr.steps % keep;
    if (rank == 0 && off_grid) {
      res.t.pop_back(), res.x.pop_back();
      if (nc > 0) res.rn.pop_back();
    }
    if (rank == 0) res.projection.Add(tr.U.data(), tr.t.size() - (off_grid ? 1 : 0), k == 0 ? 0 : 1);
    elapsed += tr.steps * h;
    PetscCallMPI(MPI_Bcast(endU.data(), (int)N, MPIU_REAL, 0, comm_));
    PetscCallMPI(MPI_Bcast(endV.data(), (int)N, MPIU_REAL, 0, comm_));
    transient.u0 = endU, transient.du0 = endV;
    res.chunks  = k + 1;
    res.periods = elapsed / res.T_ref;
    PetscCall(Analyse(res));
    if (stopped) break;
    const steady::Levels &L = res.signal.levels;
    char nr[64] = "";
    if (!res.rn.empty())
      std::snprintf(nr, sizeof nr, "; normal reaction's +- %.1f %%, drift %.1f %%", 100 * (double)res.normal.rel_halfwidth,
                    100 * (double)res.normal.drift);
    PetscCall(PetscPrintf(comm_,
                          "steady state: chunk %" PetscInt_FMT ", %.0f periods (t = %.4g s): RMS of DOF %" PetscInt_FMT
                          " %.4e +- %.1f %%, drift %.1f %%%s: %s\n",
                          k + 1, (double)res.periods, (double)elapsed, res.dof, (double)L.rms, 100 * (double)L.rel_halfwidth,
                          100 * (double)L.drift, nr,
                          res.converged ? "converged" : (k + 1 >= max_chunks ? "budget reached" : "running on")));
    if (monitor_) {
      PetscCall(PetscViewerPushFormat(monitor_, monitor_format_));
      PetscCall(View(res, monitor_));
      PetscCall(PetscViewerPopFormat(monitor_));
    }
    if (k + 1 >= max_chunks) {
      res.complete = true;
      break;
    }
    res.complete = res.converged;
  }
  res.seconds  = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::View(const SteadyStateResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  const steady::Analysis &a = res.signal;
  const steady::Levels   &L = a.levels;
  const double            tcut = res.t.size() > a.cut ? res.t[a.cut] : 0.0;
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "statistical steady state of DOF %" PetscInt_FMT " from %s: %.0f periods of %.6g s in %" PetscInt_FMT
                                   " chunk(s), %zu records, start-up dropped before t = %.6g s (MSER on the power per period)\n",
                                   res.dof, res.start.c_str(), (double)res.periods, (double)res.T_ref, res.chunks, res.t.size(), tcut));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "RMS %.4e (95 %% interval %.4e to %.4e, half-width %.1f %%, drift over the record %.1f %%), peak %.4e: %s\n",
                                   L.rms, L.rms_lo, L.rms_hi, 100 * L.rel_halfwidth, 100 * L.drift, L.peak,
                                   res.converged ? "converged" : "NOT converged (raise -steady_max_periods)"));
  if (!res.rn.empty())
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "total normal reaction: mean %.6g N, RMS about it %.4e N (95 %% interval %.4e to %.4e, drift %.1f %%), peak %.4e N\n",
                                     res.normal.mean, res.normal.rms, res.normal.rms_lo, res.normal.rms_hi, 100 * res.normal.drift, res.normal.peak));
  std::vector<size_t> order(a.lines.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t p, size_t q) { return a.amplitudes[p] > a.amplitudes[q]; });
  for (size_t i : order)
    PetscCall(PetscViewerASCIIPrintf(viewer, "line %14.6f Hz  amplitude %.4e  %s\n", a.lines[i], a.amplitudes[i], a.cls.names[i].c_str()));
  PetscCall(PetscViewerASCIIPrintf(viewer, "verdict: %s (%s)\n", a.cls.verdict.c_str(), a.cls.evidence.c_str()));
  const steady::ModalProjection::Result &q = res.modal;
  if (!q.rms.empty() && q.rms.size() == res.mode_index.size()) {
    const double tq = res.t.size() > q.from ? res.t[q.from] : 0.0;
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "unstable modes (least-squares fit of the states on Re phi, Im phi from t = %.6g s, %zu records; shapes' "
                                     "condition number %.3g):\n",
                                     tq, q.records, q.cond));
    PetscCall(PetscViewerASCIIPushTab(viewer));
    for (size_t j = 0; j < q.rms.size(); ++j)
      PetscCall(PetscViewerASCIIPrintf(viewer, "mode %" PetscInt_FMT " (%.2f Hz, growth rate %.4g 1/s): modal RMS %.4e, share of the motion %.1f %%\n",
                                       res.mode_index[j], (double)res.mode_frequency[j], (double)res.mode_growth[j], q.rms[j], 100 * q.share[j]));
    PetscCall(PetscViewerASCIIPrintf(viewer, "together they explain %.1f %% of the motion's variance; residual %.1f %%\n", 100 * q.explained,
                                     100 * (1 - q.explained)));
    PetscCall(PetscViewerASCIIPopTab(viewer));
  } else if (!res.modal_note.empty())
    PetscCall(PetscViewerASCIIPrintf(viewer, "unstable modes: no projection (%s)\n", res.modal_note.c_str()));
  if (!res.interrupted.empty()) PetscCall(PetscViewerASCIIPrintf(viewer, "%s\n", res.interrupted.c_str()));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::ViewFromOptions(const SteadyStateResult &res) const
{
  PetscFunctionBeginUser;
  PetscCall(squeal::ViewFromOptions(comm_, "steady_", [&](PetscViewer v) { return View(res, v); }));
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::Write(const SteadyStateResult &res, io::H5Writer &out) const
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  const steady::Analysis &a = res.signal;
  const steady::Levels   &L = a.levels;
  // Sizes from rank 0 (the records and the analysis are there).
  unsigned long long n[4] = {a.freq.size(), a.lines.size(), res.t.size() - std::min(res.t.size(), a.cut), res.rn.empty() ? 0ull : 1ull};
  PetscCallMPI(MPI_Bcast(n, 4, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  PetscCall(out.WriteArray("/steady_state/psd_frequency", {n[0]}, a.freq.data()));
  PetscCall(out.WriteArray("/steady_state/psd", {n[0]}, a.psd.data()));
  PetscCall(out.WriteArray("/steady_state/lines", {n[1]}, a.lines.data()));
  PetscCall(out.WriteArray("/steady_state/line_amplitudes", {n[1]}, a.amplitudes.data()));
  // The analysed records after the cut: plotted without the transient's records.
  PetscCall(out.WriteArray("/steady_state/t", {n[2]}, rank == 0 ? res.t.data() + a.cut : nullptr));
  PetscCall(out.WriteArray("/steady_state/signal", {n[2]}, rank == 0 ? res.x.data() + a.cut : nullptr));
  if (n[3]) PetscCall(out.WriteArray("/steady_state/normal_reaction", {n[2]}, rank == 0 ? res.rn.data() + a.cut : nullptr));
  const char *g = "/steady_state";
  std::string names;
  for (size_t i = 0; i < a.cls.names.size(); ++i) names += (i ? "; " : "") + a.cls.names[i];
  PetscCall(out.WriteAttribute(g, "line_names", names.c_str()));
  PetscCall(out.WriteAttribute(g, "dof", res.dof));
  PetscCall(out.WriteAttribute(g, "t_cut", (PetscReal)(res.t.size() > a.cut ? res.t[a.cut] : 0.0)));
  PetscCall(out.WriteAttribute(g, "rms", (PetscReal)L.rms));
  PetscCall(out.WriteAttribute(g, "rms_lo", (PetscReal)L.rms_lo));
  PetscCall(out.WriteAttribute(g, "rms_hi", (PetscReal)L.rms_hi));
  PetscCall(out.WriteAttribute(g, "peak", (PetscReal)L.peak));
  PetscCall(out.WriteAttribute(g, "converged", (PetscInt)res.converged));
  PetscCall(out.WriteAttribute(g, "drift", (PetscReal)L.drift));
  PetscCall(out.WriteAttribute(g, "verdict", a.cls.verdict.c_str()));
  PetscCall(out.WriteAttribute(g, "evidence", a.cls.evidence.c_str()));
  PetscCall(out.WriteAttribute(g, "bases", std::vector<PetscReal>(a.cls.bases.begin(), a.cls.bases.end())));
  PetscCall(out.WriteAttribute(g, "rtol", rtol));
  PetscCall(out.WriteAttribute(g, "batches", batches));
  PetscCall(out.WriteAttribute(g, "chunks", res.chunks));
  PetscCall(out.WriteAttribute(g, "periods", res.periods));
  PetscCall(out.WriteAttribute(g, "T_ref", res.T_ref));
  PetscCall(out.WriteAttribute(g, "start", res.start.c_str()));
  if (n[3]) {
    PetscCall(out.WriteAttribute(g, "normal_mean", (PetscReal)res.normal.mean));
    PetscCall(out.WriteAttribute(g, "normal_rms", (PetscReal)res.normal.rms));
    PetscCall(out.WriteAttribute(g, "normal_rms_lo", (PetscReal)res.normal.rms_lo));
    PetscCall(out.WriteAttribute(g, "normal_rms_hi", (PetscReal)res.normal.rms_hi));
    PetscCall(out.WriteAttribute(g, "normal_peak", (PetscReal)res.normal.peak));
  }
  // The modal projection: per unstable mode (the script's mode_rms, and more).
  unsigned long long nm[2] = {res.modal.rms.size(), (unsigned long long)res.modal.q.rows()};
  PetscCallMPI(MPI_Bcast(nm, 2, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  if (nm[0]) {
    std::vector<PetscReal> idx(res.mode_index.begin(), res.mode_index.end());
    PetscCall(out.WriteArray("/steady_state/mode_index", {nm[0]}, idx.data()));
    PetscCall(out.WriteArray("/steady_state/mode_frequency", {nm[0]}, res.mode_frequency.data()));
    PetscCall(out.WriteArray("/steady_state/mode_growth_rate", {nm[0]}, res.mode_growth.data()));
    PetscCall(out.WriteArray("/steady_state/mode_rms", {nm[0]}, res.modal.rms.data()));
    PetscCall(out.WriteArray("/steady_state/mode_share", {nm[0]}, res.modal.share.data()));
    // Row-major records x 2k (a_j, b_j): Eigen's default is column-major.
    std::vector<PetscReal> qrow;
    if (rank == 0) {
      const Eigen::MatrixXd &Q = res.modal.q;
      qrow.resize((size_t)Q.size());
      for (Eigen::Index i = 0; i < Q.rows(); ++i)
        for (Eigen::Index c = 0; c < Q.cols(); ++c) qrow[(size_t)(i * Q.cols() + c)] = Q(i, c);
    }
    PetscCall(out.WriteArray("/steady_state/modal_coordinates", {nm[1], 2 * nm[0]}, qrow.data()));
    PetscCall(out.WriteAttribute(g, "modes_explained", (PetscReal)res.modal.explained));
    PetscCall(out.WriteAttribute(g, "modes_residual", (PetscReal)(1 - res.modal.explained)));
    PetscCall(out.WriteAttribute(g, "modes_variance", (PetscReal)res.modal.variance));
    PetscCall(out.WriteAttribute(g, "modes_condition", (PetscReal)res.modal.cond));
    PetscCall(out.WriteAttribute(g, "modes_from", (PetscInt)res.modal.from));
    PetscCall(out.WriteAttribute(g, "modes_t_from", (PetscReal)(res.t.size() > res.modal.from ? res.t[res.modal.from] : 0.0)));
    PetscCall(out.WriteAttribute(g, "modes_method",
                                 "least-squares fit of the state records (window mean removed) on Re phi_j, Im phi_j of /stability/modes: "
                                 "u - mean ~ sum_j Re(phi_j q_j), q_j = a_j - i b_j; mode_rms = sqrt(mean |q_j|^2); mode_share = mean "
                                 "|Re(phi_j q_j)|^2 / mean |u - mean|^2; the window from the first checkpoint at or after the start-up cut"));
  } else {
    std::string note = rank == 0 ? res.modal_note : std::string();
    if (rank == 0 && note.empty()) note = "no records to project";
    PetscCall(out.WriteAttribute(g, "modes_note", note.c_str()));
  }
  if (!res.interrupted.empty()) PetscCall(out.WriteAttribute(g, "interrupted", res.interrupted.c_str()));
  PetscCall(out.WriteAttribute(g, "method",
                               "squeal SteadyState (C++): MSER start-up cut on the power per period; batch-means 95 % interval; Welch PSD "
                               "(Hann, 50 % overlap); lines refined by least-squares sinusoids; transient run on in chunks until converged"));
  PetscFunctionReturn(0);
}

} // namespace squeal
