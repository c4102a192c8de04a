// imuemud's main(): the service is daemon/service/imuemud_app.cpp. Only this
// file sees IMUEMU_VERSION_TEXT, so a new commit recompiles one small file.
#include "daemon/service/imuemud.hpp"

int main(int argc, char** argv) { return imuemu::service::run_imuemud(argc, argv, IMUEMU_VERSION_TEXT); }
