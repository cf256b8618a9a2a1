// Error values for everything that reads outside data or checks a request.
//
// The library never throws for bad input and never logs: a function that can
// fail on data returns gmr::Result<T>, which holds either the value or an Error
// saying where (file, line, column, when known) and what went wrong.
#pragma once

#include <cassert>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace gmr {

// One problem found in a file, a request or a call. line and column are
// 1-based; 0 means "not known / not applicable".
struct Error {
  std::string file;     // path or a label such as "<memory>"; may be empty
  int line = 0;
  int column = 0;
  std::string message;  // what was expected / what is wrong, one line

  // "file:line:column: message", leaving out the parts that are unknown.
  std::string to_string() const;
};

// Non-fatal findings of a reader (e.g. a frame count that is off by one).
using Warnings = std::vector<Error>;

// Either a T or an Error. Cheap to move; check ok() before value().
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}          // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}      // NOLINT(google-explicit-constructor)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & { assert(ok()); return std::get<0>(v_); }
  const T& value() const& { assert(ok()); return std::get<0>(v_); }
  T&& value() && { assert(ok()); return std::get<0>(std::move(v_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const { assert(!ok()); return std::get<1>(v_); }

 private:
  std::variant<T, Error> v_;
};

// Result for functions that return nothing on success.
struct Ok {};
using Status = Result<Ok>;

// Shorthand to build an Error with no location.
inline Error make_error(std::string message) { return Error{{}, 0, 0, std::move(message)}; }

}  // namespace gmr
