#pragma once

#include <ostream>
#include <string>
#include <vector>

namespace cell::cellctl {

/// A plain-text table for cellctl's human output: left-aligned columns two spaces apart,
/// trailing blanks trimmed. Not thread-safe.
class Table {
 public:
  /// A table with these column headers.
  explicit Table(std::vector<std::string> headers);

  /// Appends a column header (before any row is added).
  void add_column(std::string header);

  /// Appends a row; missing cells print empty, extra cells are kept.
  void add_row(std::vector<std::string> cells);

  /// Writes the header line and every row, each ended by '\n'.
  void print(std::ostream& out) const;

 private:
  std::vector<std::vector<std::string>> rows_;  // rows_[0] holds the headers
};

}  // namespace cell::cellctl
