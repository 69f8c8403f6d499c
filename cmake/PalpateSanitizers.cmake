# PALPATE_SANITIZE (address,undefined or thread): compile and link every
# target with those sanitizers. Filled in by the sanitizer work (issue 6).
