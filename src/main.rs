fn main() {
    // A bug must still end as one line and exit code 1, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("error: internal error (please report): {info}");
        std::process::exit(1);
    }));
    std::process::exit(lidarsim::cli::main());
}
