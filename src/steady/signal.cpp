// The statistics of a sampled signal (include/squeal/steady/steady_state.h, namespace steady):
// FFT, start-up cut, batch means, Welch PSD, lines, their names and verdict, and the modal
// projection of the records. The SteadyState object that runs the transient is steady_state.cpp.
#include "squeal/steady/steady_state.h"

#include <Eigen/Dense>

#include <algorithm>
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
  if (n < 2) return;
  // The last stage's twiddles, each from its own angle (not by repeated products: no accumulated
  // rounding); stage len reads every (n / len)-th. One sincos per butterfly of every stage was
  // 7 % of a 1000-period statistical run of the 782-DOF brake.
  std::vector<cd> tw(n / 2);
  for (size_t k = 0; k < n / 2; ++k) tw[k] = std::polar(1.0, -2 * M_PI * (double)k / (double)n);
  for (size_t len = 2; len <= n; len <<= 1) {
    const size_t stride = n / len;
    for (size_t i = 0; i < n; i += len)
      for (size_t k = 0; k < len / 2; ++k) {
        const cd u = a[i + k], v = a[i + k + len / 2] * tw[k * stride];
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
  // One name per line whatever the verdict: the view and the results file pair them up.
  c.names.assign(f.size(), "not named (lines carry too little power)");
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

std::string BandNote(const Analysis &a, double band_hz)
{
  if (a.lines.empty() || !(band_hz > 0) || !std::isfinite(band_hz)) return {};
  const double f = !a.cls.bases.empty() ? a.cls.bases[0]
                                        : a.lines[(size_t)(std::max_element(a.amplitudes.begin(), a.amplitudes.end()) - a.amplitudes.begin())];
  if (!(f > 1.02 * band_hz)) return {};
  char b[384];
  std::snprintf(b, sizeof b,
                "the motion's base frequency, %.6g Hz, lies above the stability band (up to %.6g Hz): the unstable modes that carry it are "
                "not among those projected on; raise -stab_fmax above %.6g Hz (the reduction's band permitting) to see them",
                f, band_hz, f);
  return b;
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
    const Eigen::VectorXd z = Q_.transpose() * y;
    z_.insert(z_.end(), z.data(), z.data() + z.size());
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
  for (size_t i = r.from; i < n; ++i) ee += e_[i], zbar += Z(i);
  zbar /= m;
  r.variance = std::max(0.0, ee / m - ubar.squaredNorm());
  const size_t k = cols_.size(), ncol = (size_t)Q_.cols();
  r.q            = Eigen::MatrixXd::Zero((Eigen::Index)r.records, (Eigen::Index)(2 * k));
  Eigen::MatrixXd coef((Eigen::Index)ncol, (Eigen::Index)r.records);
  double          fitted = 0;
  for (size_t i = r.from; i < n; ++i) {
    const Eigen::VectorXd dz = Z(i) - zbar;
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

} // namespace squeal
