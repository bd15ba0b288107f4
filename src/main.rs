//! The `annotrace` command: parses arguments and hands them to `cli`.

mod cli;

fn main() -> std::process::ExitCode {
    keep_freed_memory();
    cli::main()
}

/// Tells glibc's allocator to keep freed memory for reuse instead of handing blocks of a few hundred
/// kilobytes back to the kernel at every free (its default for blocks above its mmap threshold).
/// The trace writers allocate and free such buffers per trace and per Parquet page, and every
/// fresh mapping costs page faults; with several threads the mapping and unmapping also contend
/// for the process's memory map (docs/performance.md, "The frame path"). Blocks up to 32 MiB now
/// come from the heap, and freed memory is returned only above 256 MiB of free space at its top.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}
