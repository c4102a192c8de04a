// `imuemu budget`: the link budget of one device configuration, from the real
// encoder (drivers/link_budget.hpp): bytes per sample x rate against a UART,
// or the CAN frames one second of samples produces against a CAN bus, with
// worst-case framing and bit stuffing.
#pragma once

namespace CLI {
class App;
}

namespace imuemu::cli {

// Exit code: 0 ok or warn (the warning is printed), kCannotProcess when the
// traffic does not fit (refused), kUsageError for bad options.
void add_budget_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
