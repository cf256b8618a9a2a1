// Names that cross a process boundary (live source and joint names from a
// publisher or another replica, anything a server sends a client) meet one
// rule, and whatever a program prints of another's text is made safe for a
// terminal first.
#pragma once

#include <string>
#include <string_view>

namespace gmr {

// Why `name` cannot be a name (empty: it can). A name is valid UTF-8 of at
// most `max_bytes` bytes, not empty, without leading or trailing spaces, and
// without control characters (C0, DEL, C1), invisible format characters
// (zero-width spaces and joiners, bidirectional marks, embeddings, overrides
// and isolates, the byte-order mark, interlinear annotation) or spaces other
// than U+0020 (no-break, ideographic and the other typographic spaces), any
// of which would make two names look alike or change what a terminal shows.
std::string name_problem(std::string_view name, std::size_t max_bytes = 200);

// `text` with every character name_problem() refuses, and every byte that is
// not valid UTF-8, written as an escape: \n, \t, \xNN (a byte) or \u{XXXX} (a
// character). What a terminal then shows is what the text holds.
std::string terminal_safe(std::string_view text);

}  // namespace gmr
