# GMR_SANITIZE=ON builds everything with ASan and UBSan; any report aborts the
# process so a test that trips one fails. GMR_SANITIZED tells the code (the
# same with GCC and clang, which spell their own macros differently).
if(GMR_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer -g)
  add_link_options(-fsanitize=address,undefined)
  add_compile_definitions(GMR_SANITIZED=1)
endif()
