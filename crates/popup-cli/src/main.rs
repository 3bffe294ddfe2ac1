fn main() {
    std::process::exit(popup_cli::run_from_args(std::env::args_os()));
}
