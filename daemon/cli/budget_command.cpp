// `imuemu budget`: see budget_command.hpp.
#include "daemon/cli/budget_command.hpp"

#include <CLI/CLI.hpp>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "drivers/link_budget.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/transport.hpp"

namespace imuemu::cli {

void add_budget_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string protocol;
    double rate_hz = 400.0;
    drivers::SerialSettings serial;
    std::string parity = "none";
    drivers::CanBitRates can_rates;
    bool brs = false;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  std::vector<std::string> protocols = drivers::stream_protocol_names();
  for (const auto& n : drivers::can_protocol_names()) protocols.push_back(n);

  auto* c = app.add_subcommand("budget", "Link budget of a device: the real encoder's traffic against the UART (its outputs as configured at power-up; the worst case of every output beside it) or CAN bus (worst-case stuffing); warns above 70 %, refuses above 100 %");
  c->add_option("--protocol", o->protocol, "Wire protocol")->required()->check(CLI::IsMember(protocols));
  c->add_option("--rate", o->rate_hz, "Sample rate (Hz)")->capture_default_str()->check(finite_in(0.0, 1e6, true));
  c->add_option("--baud", o->serial.baud, "UART: baud rate")->capture_default_str()->check(CLI::PositiveNumber);
  c->add_option("--data-bits", o->serial.data_bits, "UART: data bits")->capture_default_str()->check(CLI::Range(5, 8));
  c->add_option("--parity", o->parity, "UART: none|odd|even|mark|space")->capture_default_str()
      ->check(CLI::IsMember({"none", "odd", "even", "mark", "space"}));
  c->add_option("--stop-bits", o->serial.stop_bits, "UART: 1 or 2")->capture_default_str()->check(CLI::IsMember({1, 2}));
  c->add_option("--bitrate", o->can_rates.nominal_bit_rate, "CAN: nominal bit rate")->capture_default_str()->check(finite_in(0.0, 1e9, true));
  c->add_option("--data-bitrate", o->can_rates.data_bit_rate, "CAN FD: data phase bit rate (frames with BRS)")->capture_default_str()
      ->check(finite_in(0.0, 1e9, true));
  c->add_flag("--brs", o->brs, "CAN FD frames use the bit rate switch");
  c->add_flag("--json", o->json, "Print the budget as one JSON object");

  c->callback([o, &exit_code] {
    try {
      drivers::LinkBudget budget;
      const bool can = o->protocol == "dronecan" || o->protocol == "j1939";
      if (can) {
        auto encoder = drivers::make_can_encoder(o->protocol);
        budget = drivers::can_budget(drivers::measure_can_traffic(*encoder, o->rate_hz, o->brs), o->can_rates);
        std::ostringstream prefix;
        prefix << o->protocol << " at " << o->rate_hz << " Hz: ";
        budget.message = prefix.str() + budget.message;
      } else {
        drivers::SerialSettings serial = o->serial;
        serial.parity = drivers::parse_parity(o->parity);
        drivers::StreamEncoderOptions so;
        so.nominal_sample_rate_hz = o->rate_hz;  // spreads the heartbeat over the samples
        auto encoder = drivers::make_stream_encoder(o->protocol, so);
        budget = drivers::uart_budget(*encoder, o->rate_hz, serial);
      }
      if (o->json) {
        nlohmann::json j{{"protocol", o->protocol},
                         {"rate_hz", o->rate_hz},
                         {"load_fraction", budget.load_fraction},
                         {"bits_per_second_used", budget.bits_per_second_used},
                         {"capacity_bits_per_second", budget.capacity_bits_per_second},
                         {"verdict", drivers::to_string(budget.verdict)},
                         {"message", budget.message}};
        // UART: every output on every sample, beside the configured outputs the verdict is on.
        if (budget.worst_case_load_fraction) {
          j["worst_case_bytes_per_second"] = *budget.worst_case_bytes_per_second;
          j["worst_case_load_fraction"] = *budget.worst_case_load_fraction;
        }
        std::cout << j.dump() << "\n";
      } else {
        std::cout << budget.message << "\n";
      }
      exit_code = budget.verdict == drivers::BudgetVerdict::refuse ? kCannotProcess : kOk;
    } catch (const std::exception& e) {  // invalid_argument, TransportError: bad settings
      std::cerr << "imuemu budget: " << e.what() << "\n";
      exit_code = kUsageError;
    }
  });
}

}  // namespace imuemu::cli
