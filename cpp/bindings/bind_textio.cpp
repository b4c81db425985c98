// Numeric text tables: _core.write_table (the solution writer) and
// _core.parse_text (the KF-GINS and insnav CSV readers), on
// insnav/io/text_table.hpp with the GIL released.  The writer checks for
// Ctrl-C after each of its blocks (taking the GIL only for that check).
#include <pybind11/stl.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#if defined(__unix__) || defined(__APPLE__)
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#define INSNAV_POSIX_IO 1
#endif
#include <optional>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/io/text_table.hpp"
#include "outputs.hpp"

namespace insnav::py_bind {

namespace {

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};

/// The columns of a write_table call, checked (the arrays referenced in `keep` while the GIL is released).
std::vector<textio::Column> table_columns(const py::list& columns, const std::vector<double>& scales,
                                          const std::vector<int>& decimals, const std::string& sep,
                                          std::vector<py::array>& keep, py::ssize_t& n) {
  const std::size_t nc = columns.size();
  if (nc == 0 || scales.size() != nc || decimals.size() != nc)
    throw py::value_error("write_table: columns, scales and decimals must have the same (non-zero) length");
  if (sep.size() != 1) throw py::value_error("write_table: the separator must be one character");
  std::vector<textio::Column> cols(nc);
  n = -1;
  for (std::size_t j = 0; j < nc; ++j) {
    py::array a = py::reinterpret_borrow<py::array>(columns[j]);
    if (!py::isinstance<py::array>(columns[j]) || a.ndim() != 1 || !a.dtype().is(py::dtype::of<double>()))
      throw py::value_error("write_table: column " + std::to_string(j) + " is not a 1-D float64 array");
    if (n < 0) n = a.shape(0);
    if (a.shape(0) != n) throw py::value_error("write_table: columns of different lengths");
    if (a.strides(0) % static_cast<py::ssize_t>(sizeof(double)) != 0)
      throw py::value_error("write_table: unaligned column stride");
    cols[j] = {static_cast<const double*>(a.data()), a.strides(0) / static_cast<py::ssize_t>(sizeof(double)),
               scales[j], decimals[j]};
    keep.push_back(a);
  }
  return cols;
}

textio::TextFormat text_format(const std::string& sep, int width, bool trim_zeros, bool trailing_sep) {
  textio::TextFormat fmt;
  fmt.sep = sep[0];
  fmt.width = width;
  fmt.trim_zeros = trim_zeros;
  fmt.trailing_sep = trailing_sep;
  return fmt;
}

[[noreturn]] void raise_os_error(int e, const std::string& path) {
  errno = e;
  PyErr_SetFromErrnoWithFilename(PyExc_OSError, path.c_str());
  throw py::error_already_set();
}

/// The header and the rows into `sink` (GIL released; Ctrl-C checked after each block).
template <class Sink>
textio::WriteResult write_into(Sink& sink, const std::string& header, const std::vector<textio::Column>& cols,
                               py::ssize_t n, const textio::TextFormat& fmt, int threads, bool& interrupted,
                               textio::TextBuffer* buffers = nullptr) {
  textio::WriteResult res;
  py::gil_scoped_release release;
  if (const int e = sink(header.data(), header.size()); e != 0) {
    res.status = textio::WriteStatus::kIoError;
    res.error = e;
    return res;
  }
  res = textio::write_rows_to(sink, cols.data(), static_cast<int>(cols.size()), n, fmt, threads, 8192, [&] {
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) interrupted = true;
    return !interrupted;
  }, buffers);
  res.bytes += static_cast<std::int64_t>(header.size());
  return res;
}

py::int_ write_table(const std::string& path, const std::string& header, const py::list& columns,
                     const std::vector<double>& scales, const std::vector<int>& decimals, const std::string& sep,
                     int width, bool trim_zeros, bool trailing_sep, int threads, bool append) {
  std::vector<py::array> keep;  // the arrays stay referenced while the GIL is released
  py::ssize_t n = 0;
  const std::vector<textio::Column> cols = table_columns(columns, scales, decimals, sep, keep, n);
  const textio::TextFormat fmt = text_format(sep, width, trim_zeros, trailing_sep);
  bool interrupted = false;
  textio::WriteResult res;
  if (!append) {  // the whole file: through an aligned buffer with O_DIRECT (direct_file.hpp)
    textio::DirectFile f(path);
    if (f.error() != 0) raise_os_error(f.error(), path);
    auto put = [&f](const char* p, std::size_t k) { return f.write(p, k); };
    res = write_into(put, header, cols, n, fmt, threads, interrupted);
    const int e = f.close();
    if (interrupted) throw py::error_already_set();  // KeyboardInterrupt from the signal handler
    if (res.status == textio::WriteStatus::kOk && e != 0) raise_os_error(e, path);
    if (res.status == textio::WriteStatus::kIoError) raise_os_error(res.error, path);
    return py::int_(res.bytes);
  }
  // append: the rows go after the file's end
  std::unique_ptr<std::FILE, FileCloser> f(std::fopen(path.c_str(), "ab"));
  if (!f) raise_os_error(errno, path);
  std::FILE* fp = f.get();
  auto put = [fp](const char* p, std::size_t k) { return std::fwrite(p, 1, k, fp) == k ? 0 : (errno ? errno : EIO); };
  res = write_into(put, header, cols, n, fmt, threads, interrupted);
  if (res.status == textio::WriteStatus::kOk && std::fflush(fp) != 0) {
    res.status = textio::WriteStatus::kIoError;
    res.error = errno;
  }
  if (interrupted) throw py::error_already_set();
  const int close_rc = std::fclose(f.release());
  if (res.status == textio::WriteStatus::kOk && close_rc != 0) {
    res.status = textio::WriteStatus::kIoError;
    res.error = errno;
  }
  if (res.status == textio::WriteStatus::kIoError) raise_os_error(res.error, path);
  return py::int_(res.bytes);
}

/// _core.TextSink: one text file written by several write_table calls (a
/// solution written block by block, filters/stream.py), through a
/// DirectFile kept open between them (O_DIRECT needs aligned offsets, which
/// a file reopened for appending after each block does not have).
struct TextSink {
  std::string path;
  std::unique_ptr<textio::DirectFile> file;
  std::vector<textio::TextBuffer> buffers;  // one per formatting thread, kept across the calls
  std::int64_t closed_bytes = -1;

  TextSink(const std::string& p, bool direct) : path(p), file(std::make_unique<textio::DirectFile>(p, direct)) {
    if (file->error() != 0) raise_os_error(file->error(), path);
  }

  py::int_ write(const std::string& header, const py::list& columns, const std::vector<double>& scales,
                 const std::vector<int>& decimals, const std::string& sep, int width, bool trim_zeros,
                 bool trailing_sep, int threads) {
    if (!file) throw py::value_error("TextSink.write after close(): " + path);
    std::vector<py::array> keep;
    py::ssize_t n = 0;
    const std::vector<textio::Column> cols = table_columns(columns, scales, decimals, sep, keep, n);
    const textio::TextFormat fmt = text_format(sep, width, trim_zeros, trailing_sep);
    bool interrupted = false;
    textio::DirectFile& f = *file;
    auto put = [&f](const char* p, std::size_t k) { return f.write(p, k); };
    threads = std::max(1, threads);
    if (buffers.size() < static_cast<std::size_t>(threads)) buffers.resize(static_cast<std::size_t>(threads));
    const textio::WriteResult res = write_into(put, header, cols, n, fmt, threads, interrupted, buffers.data());
    if (interrupted) throw py::error_already_set();
    if (res.status == textio::WriteStatus::kIoError) raise_os_error(res.error, path);
    return py::int_(res.bytes);
  }

  py::int_ close() {
    if (file) {
      int e = 0;
      {
        py::gil_scoped_release release;
        e = file->close();
      }
      closed_bytes = file->bytes();
      file.reset();
      if (e != 0) raise_os_error(e, path);
    }
    return py::int_(closed_bytes < 0 ? 0 : closed_bytes);
  }
};

py::tuple parse_text(const py::buffer& data, int ncols, int keep, bool allow_extra, bool comma,
                     std::int64_t first_line, int threads, const std::optional<std::vector<int>>& groups) {
  if (ncols <= 0 || keep <= 0 || keep > ncols) throw py::value_error("parse_text: need 0 < keep <= ncols");
  std::vector<int> widths = groups ? *groups : std::vector<int>{keep};
  int total = 0;
  for (int w : widths) {
    if (w <= 0) throw py::value_error("parse_text: group widths must be > 0");
    total += w;
  }
  if (total != keep) throw py::value_error("parse_text: the group widths must add up to keep");
  const py::buffer_info info = data.request();
  if (info.ndim != 1 || info.itemsize != 1) throw py::value_error("parse_text: expected a bytes-like buffer");
  const char* p = static_cast<const char*>(info.ptr);
  const std::size_t size = static_cast<std::size_t>(info.size);
  textio::ParsePlan plan;
  {
    py::gil_scoped_release release;
    plan = textio::plan_parse(p, size, threads);  // lines counted on the parse's threads
  }
  const auto lines = static_cast<py::ssize_t>(plan.total_lines);
  // one array per group, (lines, width) (a width of 1 without groups still 2-D); pages untouched until parsed
  std::vector<DArray> outs;
  std::vector<textio::ColumnSink> sinks;
  for (int w : widths) {
    const bool flat = groups && w == 1;
    outs.push_back(flat ? DArray({lines}) : DArray({lines, static_cast<py::ssize_t>(w)}));
    double* base = outs.back().mutable_data();
    for (int j = 0; j < w; ++j) sinks.push_back({base + j, w});
  }
  py::array_t<std::int64_t> line_of(lines);  // written only when a line was blank
  textio::ParseOptions opt;
  opt.ncols = ncols;
  opt.keep = keep;
  opt.allow_extra = allow_extra;
  opt.comma = comma;
  textio::ParseResult res;
  {
    py::gil_scoped_release release;
    res = textio::parse_planned(p, plan, opt, first_line, sinks.data(), line_of.mutable_data());
  }
  py::object err = py::none();
  if (res.error.kind != textio::ParseErrorKind::kNone) {
    const auto& e = res.error;
    err = py::make_tuple(static_cast<int>(e.kind), e.line, e.found, e.column, e.token_begin, e.token_end,
                         e.line_end);
  }
  const py::slice rows(0, static_cast<py::ssize_t>(res.rows), 1);
  py::object lines_out = res.blank ? py::object(line_of[rows]) : py::object(py::none());
  py::object arrays;
  if (groups) {
    py::tuple t(outs.size());
    for (std::size_t g = 0; g < outs.size(); ++g) t[g] = outs[g][rows];
    arrays = t;
  } else {
    arrays = outs[0][rows];
  }
  return py::make_tuple(arrays, lines_out, err);
}


py::tuple parse_csv(const py::buffer& data, std::size_t begin, char delim, int nfields, const std::vector<int>& want,
                    int time_want) {
  const py::buffer_info info = data.request();
  if (info.ndim != 1 || info.itemsize != 1) throw py::value_error("parse_csv: expected a bytes-like buffer");
  const std::size_t size = static_cast<std::size_t>(info.size);
  if (begin > size) throw py::value_error("parse_csv: begin past the end of the buffer");
  if (want.empty() || nfields <= 0 || time_want >= static_cast<int>(want.size()))
    throw py::value_error("parse_csv: bad field layout");
  for (int f : want)
    if (f < 0 || f >= nfields) throw py::value_error("parse_csv: a wanted field out of range");
  textio::CsvFieldOptions opt;
  opt.delim = delim;
  opt.nfields = nfields;
  opt.want = want;
  opt.time_want = time_want;
  const char* p = static_cast<const char*>(info.ptr);
  std::int64_t nlines = 0;
  {
    py::gil_scoped_release release;
    nlines = textio::count_lines(p + begin, p + size);
  }
  const auto n = static_cast<py::ssize_t>(nlines);  // one row a line at most; pages untouched until parsed
  DArray values({n, static_cast<py::ssize_t>(want.size())});
  py::array_t<std::int64_t> line(n), t_hi(time_want >= 0 ? n : 0), t_lo(time_want >= 0 ? n : 0);
  DArray t_frac({time_want >= 0 ? n : 0});
  py::array_t<std::uint8_t> t_kind(time_want >= 0 ? n : 0);
  textio::CsvSinks sinks{values.mutable_data(), line.mutable_data(), t_hi.mutable_data(), t_lo.mutable_data(),
                         t_frac.mutable_data(), t_kind.mutable_data()};
  textio::CsvParsed res;
  {
    py::gil_scoped_release release;
    res = textio::parse_csv_fields(p, begin, size, opt, sinks);
  }
  const py::slice rows(0, static_cast<py::ssize_t>(res.rows), 1);
  py::object split = py::none();
  if (time_want >= 0) split = py::make_tuple(t_hi[rows], t_lo[rows], t_frac[rows], t_kind[rows]);
  return py::make_tuple(values[rows], line[rows], split, res.lines, res.stopped ? py::object(py::int_(res.stop_pos))
                                                                                 : py::object(py::none()));
}
}  // namespace

void bind_textio(py::module_& m) {
  m.def(
      "set_progress",
      [](const py::object& f) {
        PyObject*& hook = progress_hook();
        Py_XDECREF(hook);
        hook = nullptr;
        if (!f.is_none()) hook = py::object(f).release().ptr();
      },
      py::arg("callback"),
      "Call callback(k, n) from every run's C++ loop at most every 20 ms (with the GIL, beside the Ctrl-C "
      "check); None: no callback.  An exception from it stops the run.");
  m.def("write_table", &write_table, py::arg("path"), py::arg("header"), py::arg("columns"), py::arg("scales"),
        py::arg("decimals"), py::arg("sep") = ",", py::arg("width") = 0, py::arg("trim_zeros") = true,
        py::arg("trailing_sep") = false, py::arg("threads") = 2, py::arg("append") = false,
        "Write 1-D float64 columns (any stride) times their scales as a text table to path: decimals[j] >= 0 "
        "fixed (trailing zeros trimmed when trim_zeros), < 0 shortest round-trip; blocks formatted on `threads` "
        "threads, GIL released, Ctrl-C checked after each block; append: after the file's end.  Returns the "
        "bytes written.");
  py::class_<TextSink>(m, "TextSink",
                       "A text file written by several write() calls (the write_table arguments without path and "
                       "append), front to back through an aligned buffer with O_DIRECT where the file system allows "
                       "it (page cache otherwise: the same bytes); close() writes the rest and returns the bytes.")
      .def(py::init<const std::string&, bool>(), py::arg("path"), py::arg("direct") = true)
      .def("write", &TextSink::write, py::arg("header"), py::arg("columns"), py::arg("scales"), py::arg("decimals"),
           py::arg("sep") = ",", py::arg("width") = 0, py::arg("trim_zeros") = true, py::arg("trailing_sep") = false,
           py::arg("threads") = 2, "Append the header (may be empty) and the rows; returns their bytes.")
      .def("close", &TextSink::close, "Write the rest, cut an older longer file, close; returns the file's bytes.")
      .def_property_readonly("direct", [](const TextSink& s) { return s.file && s.file->direct(); },
                             "Whether the file is still written with O_DIRECT.");
  m.def("parse_csv", &parse_csv, py::arg("data"), py::arg("begin"), py::arg("delim"), py::arg("nfields"),
        py::arg("want"), py::arg("time_want"),
        "The generic IMU CSV's numeric lines from byte `begin` (text_table.hpp parse_csv_fields): nfields "
        "`delim`-separated fields a line, the fields `want` read as Python's float() does; blank and '#' lines "
        "skipped; up to the first line it does not take (time_want < 0: no time field).  Returns "
        "(values (rows, len(want)), line index of each row from `begin`'s line, None or (t_hi, t_lo, t_frac, "
        "t_kind) of want[time_want], lines taken, None or the byte where the line not taken starts).");
  m.def("parse_text", &parse_text, py::arg("data"), py::arg("ncols"), py::arg("keep"), py::arg("allow_extra") = false,
        py::arg("comma") = false, py::arg("first_line") = 1, py::arg("threads") = 2, py::arg("groups") = py::none(),
        "Parse whitespace (and with comma=True comma) separated numbers, ncols a row (more if allow_extra), "
        "keeping the first `keep`; blank lines skipped.  Returns (array (rows, keep), line of each row or None "
        "when no line was blank, None or the first error (kind 1 columns | 2 number, line, found, column, "
        "token_begin, token_end, line_end)).  groups (widths adding up to keep): the kept values split over "
        "one array per group instead, returned as a tuple ((rows,) for a width of 1, else (rows, width)).");
}

}  // namespace insnav::py_bind
