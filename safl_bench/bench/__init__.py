"""Every speed benchmark (`safl-bench bench ...`): the matcher (`matching_bench`), the
methods (`method_bench`), the top-view image source (`source_bench`) and local against
parallel map building and runs (`parallel_bench`)."""
