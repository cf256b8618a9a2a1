#include "gmr/core/error.h"

namespace gmr {

std::string Error::to_string() const {
  std::string out;
  if (!file.empty()) {
    out += file;
    if (line > 0) {
      out += ':' + std::to_string(line);
      if (column > 0) out += ':' + std::to_string(column);
    }
    out += ": ";
  } else if (line > 0) {
    out += "line " + std::to_string(line);
    if (column > 0) out += ", column " + std::to_string(column);
    out += ": ";
  }
  out += message;
  return out;
}

const char* error_kind_name(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kInvalidData: return "invalid data";
    case ErrorKind::kInvalidArgument: return "invalid argument";
    case ErrorKind::kNotFound: return "not found";
    case ErrorKind::kFailedPrecondition: return "failed precondition";
    case ErrorKind::kResourceExhausted: return "resource exhausted";
    case ErrorKind::kIo: return "i/o error";
  }
  return "unknown";
}

}  // namespace gmr
