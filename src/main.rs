fn main() {
    // A bug must still end as one line and exit code 1, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        // written, not printed: printing to a closed standard error would panic in the hook
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "error: internal error (please report): {info}"
        );
        std::process::exit(1);
    }));
    std::process::exit(lidarsim::cli::main());
}
