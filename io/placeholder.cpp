namespace imuemu::io { int placeholder() { return 0; } }
