fn main() -> std::process::ExitCode {
    werkstatt::app::cli::main()
}
