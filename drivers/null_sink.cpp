// placeholder so the library has a translation unit until a driver lands
namespace imuemu::drivers { int null_sink_placeholder() { return 0; } }
