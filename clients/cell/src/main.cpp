#include "commands.hpp"

// `cell up | down | status`: see commands.hpp and clients/cell/README.md.
int main(int argc, char** argv) { return cell::launcher::main_cli(argc, argv); }
