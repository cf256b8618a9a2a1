// Under AddressSanitizer, the network tests also catch a handler that writes
// into a stack frame that has already returned (server_lifecycle_test.cpp).
#if defined(GMR_SANITIZED)
extern "C" const char* __asan_default_options() { return "detect_stack_use_after_return=1"; }
#endif
