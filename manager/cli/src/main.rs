//! `skillfab`: see the library's [crate documentation](skillfab_cli).

fn main() -> std::process::ExitCode {
    skillfab_cli::main()
}
