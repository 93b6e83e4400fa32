fn main() -> std::process::ExitCode {
    bouncewear::cli::main()
}
