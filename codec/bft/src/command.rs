//! The commands of a BFT stream (the table in the crate's documentation).

/// The commands of the BFT stream, with `ADD` split by operand form and the paper's
/// offsets carried beside `Rf`, `Lf` and `AddRef`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Command {
    New = 0,
    Rf0 = 1,
    Lf0 = 2,
    Rf = 3,
    Lf = 4,
    Null = 5,
    Dl = 6,
    Dr = 7,
    AddNew = 8,
    AddRef = 9,
    Seed = 10,
    Clear = 11,
}

impl Command {
    /// Every command, in the order of its code (`Command::ALL[c as usize] == c`).
    pub const ALL: [Command; 12] = [
        Command::New,
        Command::Rf0,
        Command::Lf0,
        Command::Rf,
        Command::Lf,
        Command::Null,
        Command::Dl,
        Command::Dr,
        Command::AddNew,
        Command::AddRef,
        Command::Seed,
        Command::Clear,
    ];

    /// Whether the command codes a triangle.
    pub fn is_triangle(self) -> bool {
        matches!(self, Command::New | Command::Rf0 | Command::Lf0 | Command::Rf | Command::Lf | Command::Seed)
    }
}
