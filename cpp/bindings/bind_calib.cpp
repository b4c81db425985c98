// IMU calibration statistics (insnav/calib/): the overlapping Allan variance
// of several rate series in one call with the GIL released; the pure-Python
// API is insnav.calib.allan.
#include <cstdint>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/calib/allan.hpp"

namespace insnav::py_bind {

namespace {

using FArray = py::array_t<double, py::array::forcecast>;  // any strides (a column slice is not copied)

py::tuple overlapping_avar(const py::sequence& rates, const py::array_t<std::int64_t, py::array::forcecast>& m,
                           int threads) {
  std::vector<FArray> arrays;
  std::vector<calib::RateSeries> axes;
  py::ssize_t n = -1;
  for (py::size_t i = 0; i < rates.size(); ++i) {
    FArray a = FArray::ensure(rates[i]);
    if (!a) throw py::value_error("overlapping_avar: rates[" + std::to_string(i) + "] is not a float array");
    if (a.ndim() != 1 && a.ndim() != 2)
      throw py::value_error("overlapping_avar: rates[" + std::to_string(i) + "] must be 1-D (n,) or 2-D (n, k)");
    if (n < 0) n = a.shape(0);
    if (a.shape(0) != n)
      throw py::value_error("overlapping_avar: rates[" + std::to_string(i) + "] has " + std::to_string(a.shape(0)) +
                            " samples, rates[0] " + std::to_string(n));
    const py::ssize_t k = a.ndim() == 2 ? a.shape(1) : 1;
    const py::ssize_t s0 = a.strides(0), s1 = a.ndim() == 2 ? a.strides(1) : 0;
    if (s0 % static_cast<py::ssize_t>(sizeof(double)) || s1 % static_cast<py::ssize_t>(sizeof(double)))
      throw py::value_error("overlapping_avar: rates[" + std::to_string(i) + "]: strides not a multiple of 8 bytes");
    for (py::ssize_t c = 0; c < k; ++c)
      axes.push_back(calib::RateSeries{a.data() + c * (s1 / 8), static_cast<std::int64_t>(s0 / 8)});
    arrays.push_back(std::move(a));  // keeps a converted copy alive
  }
  if (axes.empty()) throw py::value_error("overlapping_avar: no rate series");
  if (n < 2) throw py::value_error("overlapping_avar: need at least 2 samples");
  if (m.ndim() != 1) throw py::value_error("overlapping_avar: m must be 1-D");
  const int n_m = static_cast<int>(m.shape(0));
  for (int j = 0; j < n_m; ++j)
    if (m.data()[j] < 1 || 2 * m.data()[j] > n)
      throw py::value_error("overlapping_avar: cluster size m = " + std::to_string(m.data()[j]) + " outside 1.." +
                            std::to_string(n / 2) + " (n = " + std::to_string(n) + " samples)");
  const int n_axes = static_cast<int>(axes.size());
  py::array_t<double> avar({static_cast<py::ssize_t>(n_m), static_cast<py::ssize_t>(n_axes)});
  py::array_t<std::int64_t> terms(n_m);
  calib::AllanStatus st;
  {
    py::gil_scoped_release release;
    st = calib::overlapping_avar(axes.data(), n_axes, n, m.data(), n_m, avar.mutable_data(), terms.mutable_data(),
                                 threads);
  }
  return py::make_tuple(avar, terms, st.bad_sample, st.bad_axis);
}

}  // namespace

void bind_calib(py::module_& m) {
  m.def("overlapping_avar", &overlapping_avar, py::arg("rates"), py::arg("m"), py::arg("threads") = 0,
        "Overlapping Allan variance (calib/allan.hpp; IEEE Std 952-1997 Annex C, NIST SP 1065 eq. (11)) of the "
        "columns of every (n,) or (n, k) float64 array in `rates` (same n; any strides, not copied) at the cluster "
        "sizes m (tau = m tau0, 1 <= m <= n/2).  Returns (avar (n_m, axes) in the rate unit squared, terms (n_m,) = "
        "n + 1 - 2m, first non-finite sample or -1, first axis of its group of three or -1).  threads <= 0: the "
        "hardware's; GIL released.");
  m.def("allan_cluster_sizes",
        [](std::int64_t n, int per_octave, std::int64_t max_m) {
          if (n < 2) throw py::value_error("allan_cluster_sizes: need n >= 2 samples");
          if (per_octave < 1 || per_octave > 64) throw py::value_error("allan_cluster_sizes: per_octave in 1..64");
          const auto v = calib::cluster_sizes(n, per_octave, max_m);
          py::array_t<std::int64_t> out(static_cast<py::ssize_t>(v.size()));
          std::copy(v.begin(), v.end(), out.mutable_data());
          return out;
        },
        py::arg("n"), py::arg("per_octave") = 1, py::arg("max_m") = -1,
        "Cluster sizes round(2^(k / per_octave)), distinct, 1 <= m <= min(max_m, n / 2) (max_m <= 0: n / 2).");
}

}  // namespace insnav::py_bind
