"""Every speed benchmark (`safl-bench bench ...`): the matcher (`matching_bench`), the
methods (`method_bench`), the top-view image source (`source_bench`), local against
parallel map building and runs (`parallel_bench`) and five seeds of a cell against one
(`seeds_bench`)."""
