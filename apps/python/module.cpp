// The Python module planeslam._planeslam (imported by the package planeslam/__init__.py).
#include <pybind11/pybind11.h>

#include <exception>

#include "planeslam/datasets/errors.hpp"
#include "py_common.hpp"

namespace {

/// planeslam's file errors become OSError and its configuration errors ValueError, with the
/// one-line messages the CLI prints.
void TranslateErrors(std::exception_ptr error) {
  try {
    if (error) std::rethrow_exception(error);
  } catch (const planeslam::IoError& e) {
    PyErr_SetString(PyExc_OSError, e.what());
  } catch (const planeslam::ConfigError& e) {
    PyErr_SetString(PyExc_ValueError, e.what());
  }
}

}  // namespace

PYBIND11_MODULE(_planeslam, m) {
  m.doc() = "planeslam: plane detection, plane SLAM and trajectory evaluation (C++ core).";
  pybind11::register_exception_translator(&TranslateErrors);
  planeslam::python::RegisterDetect(m);
  planeslam::python::RegisterSlam(m);
  planeslam::python::RegisterSequence(m);
  planeslam::python::RegisterEval(m);
}
