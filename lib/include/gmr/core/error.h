// Error values for everything that reads outside data or checks a request.
//
// The library never throws for bad input and never logs: a function that can
// fail on data returns gmr::Result<T>, which holds either the value or an Error
// saying where (file, line, column, when known) and what went wrong.
#pragma once

#include <cassert>
#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace gmr {

// What kind of problem an Error is, so a caller (the server choosing a
// protocol error code, a tool choosing an exit status) can react without
// re-checking the request itself.
enum class ErrorKind : std::uint8_t {
  kInvalidData,         // outside data (a file, a packet) is malformed; file/line/column say where
  kInvalidArgument,     // a call's or request's values are wrong in themselves (empty set, name listed twice)
  kNotFound,            // a named or numbered thing does not exist (joint, motion, file)
  kFailedPrecondition,  // valid values the current state refuses (not a root, post-rotation input)
  kResourceExhausted,   // a limit was reached (size, count)
  kIo,                  // the system refused (open, read, write, rename)
};

// One problem found in a file, a request or a call. line and column are
// 1-based; 0 means "not known / not applicable".
struct Error {
  std::string file;  // path or a label such as "<memory>"; may be empty
  int line = 0;
  int column = 0;
  std::string message;  // what was expected / what is wrong, one line
  ErrorKind kind = ErrorKind::kInvalidData;

  // "file:line:column: message", leaving out the parts that are unknown.
  std::string to_string() const;
};

// Non-fatal findings of a reader (e.g. a frame count that is off by one).
using Warnings = std::vector<Error>;

// Either a T or an Error. Cheap to move; check ok() before value().
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & {
    assert(ok());
    return std::get<0>(v_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<0>(v_);
  }
  T&& value() && {
    assert(ok());
    return std::get<0>(std::move(v_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const {
    assert(!ok());
    return std::get<1>(v_);
  }

 private:
  std::variant<T, Error> v_;
};

// Result for functions that return nothing on success.
struct Ok {};
using Status = Result<Ok>;

// Shorthands to build an Error with no location: of the given kind, or
// kInvalidArgument.
inline Error make_error(ErrorKind kind, std::string message) { return Error{{}, 0, 0, std::move(message), kind}; }
inline Error make_error(std::string message) { return make_error(ErrorKind::kInvalidArgument, std::move(message)); }

}  // namespace gmr
