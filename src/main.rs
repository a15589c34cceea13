fn main() -> std::process::ExitCode {
    werkstatt::cli::main()
}
