//! The `annotrace` command: parses arguments and hands them to `cli`.

mod cli;

/// mimalloc instead of glibc's allocator for everything Rust allocates. The traces the optimiser and
/// the detector runtime build and drop per sample are millions of small blocks; glibc's free lists
/// (`_int_free`, `malloc_consolidate`, `unlink_chunk`) were about 30 % of the CPU of a billiards
/// optimisation run (docs/performance.md, "The allocator").
#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

unsafe extern "C" {
    /// mimalloc's option setter (`mimalloc.h`; the static library is linked through the `mimalloc`
    /// crate, which does not re-export it).
    fn mi_option_set(option: std::ffi::c_int, value: std::ffi::c_long);
}

/// `mi_option_purge_delay` in mimalloc's `mi_option_e` (the same number in its v2 and v3).
const MI_OPTION_PURGE_DELAY: std::ffi::c_int = 15;

fn main() -> std::process::ExitCode {
    keep_freed_memory();
    cli::main()
}

/// Tells the allocators (mimalloc for Rust, glibc for C libraries such as zstd) to keep freed memory
/// for reuse. glibc: instead of handing blocks of a few hundred
/// kilobytes back to the kernel at every free (its default for blocks above its mmap threshold).
/// The trace writers allocate and free such buffers per trace and per Parquet page, and every
/// fresh mapping costs page faults; with several threads the mapping and unmapping also contend
/// for the process's memory map (docs/performance.md, "The frame path"). Blocks up to 32 MiB now
/// come from the heap, and freed memory is returned only above 256 MiB of free space at its top.
fn keep_freed_memory() {
    // mimalloc, by default, hands freed pages back to the kernel 10 ms after they empty; a run that
    // builds and drops a trace per sample then faults every page in again (ten times glibc's page
    // faults in an optimisation run, and 10 % of its CPU in the kernel). Never purging keeps the
    // process at its peak footprint, as the glibc settings below do.
    // SAFETY: sets an allocator option before any other thread exists.
    unsafe {
        mi_option_set(MI_OPTION_PURGE_DELAY, -1);
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}
