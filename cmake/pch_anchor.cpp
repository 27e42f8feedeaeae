// The one source of the targets that hold the project's precompiled headers
// (cmake/CellTargets.cmake, CELL_PCH): the headers are what they exist for.
