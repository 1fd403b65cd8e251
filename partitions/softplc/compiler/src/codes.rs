//! The stable codes of the compiler's diagnostics: every error the compiler reports carries
//! one (`error[E0049]: unknown variable`), and `plcc explain E0049` prints its explanation.
//! This table is the single source of the codes; `docs/plc-diagnostics.md` is generated from
//! it (`plcc explain --markdown`) and a test keeps the two equal. Codes are never renumbered
//! or reused: a retired code keeps its entry.

use std::fmt;

/// A diagnostic code, printed `E0042`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Code(u16);

impl Code {
    /// The number of the code (42 for E0042).
    pub const fn number(self) -> u16 {
        self.0
    }

    /// The table entry of the code.
    pub fn entry(self) -> &'static Entry {
        &TABLE[usize::from(self.0) - 1]
    }
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "E{:04}", self.0)
    }
}

/// One row of the table: the code, a short title and a one-paragraph explanation.
#[derive(Debug)]
pub struct Entry {
    pub code: Code,
    pub title: &'static str,
    pub explanation: &'static str,
}

/// E0001: unterminated comment or pragma.
pub const UNTERMINATED_COMMENT: Code = Code(1);
/// E0002: unterminated string literal.
pub const UNTERMINATED_STRING: Code = Code(2);
/// E0003: invalid escape sequence.
pub const INVALID_ESCAPE: Code = Code(3);
/// E0004: invalid based integer literal.
pub const INVALID_BASED_LITERAL: Code = Code(4);
/// E0005: integer literal too large.
pub const INTEGER_TOO_LARGE: Code = Code(5);
/// E0006: malformed typed or date/time literal.
pub const MALFORMED_LITERAL: Code = Code(6);
/// E0007: malformed duration literal.
pub const MALFORMED_DURATION: Code = Code(7);
/// E0008: unexpected character.
pub const UNEXPECTED_CHARACTER: Code = Code(8);
/// E0009: syntax error.
pub const SYNTAX: Code = Code(9);
/// E0010: nested too deeply.
pub const NESTED_TOO_DEEPLY: Code = Code(10);
/// E0011: element not allowed in this kind of POU.
pub const MISPLACED_POU_ELEMENT: Code = Code(11);
/// E0012: interface content.
pub const INTERFACE_CONTENT: Code = Code(12);
/// E0013: property without accessor.
pub const PROPERTY_WITHOUT_ACCESSOR: Code = Code(13);
/// E0014: misused attribute 'safe'.
pub const SAFE_ATTRIBUTE: Code = Code(14);
/// E0015: misused attribute 'shared'.
pub const SHARED_ATTRIBUTE: Code = Code(15);
/// E0016: unknown task property.
pub const UNKNOWN_TASK_PROPERTY: Code = Code(16);
/// E0017: name defined twice.
pub const DUPLICATE_DEFINITION: Code = Code(17);
/// E0018: variable declared twice.
pub const DUPLICATE_VARIABLE: Code = Code(18);
/// E0019: duplicate structure member or enumeration value.
pub const DUPLICATE_MEMBER: Code = Code(19);
/// E0020: type defined in terms of itself.
pub const RECURSIVE_TYPE: Code = Code(20);
/// E0021: unknown type.
pub const UNKNOWN_TYPE: Code = Code(21);
/// E0022: ambiguous name.
pub const AMBIGUOUS_NAME: Code = Code(22);
/// E0023: constant expression required.
pub const NOT_CONSTANT: Code = Code(23);
/// E0024: invalid string length.
pub const STRING_LENGTH: Code = Code(24);
/// E0025: invalid array bounds.
pub const ARRAY_BOUNDS: Code = Code(25);
/// E0026: invalid subrange.
pub const INVALID_SUBRANGE: Code = Code(26);
/// E0027: reference to a reference.
pub const REFERENCE_TO_REFERENCE: Code = Code(27);
/// E0028: anonymous enumeration or structure.
pub const ANONYMOUS_TYPE: Code = Code(28);
/// E0029: function block instance not allowed here.
pub const FB_INSTANCE_NOT_ALLOWED: Code = Code(29);
/// E0030: variable block not allowed in this POU.
pub const VAR_BLOCK_NOT_ALLOWED: Code = Code(30);
/// E0031: VAR_IN_OUT with an initial value.
pub const INOUT_INITIAL_VALUE: Code = Code(31);
/// E0032: constant without a value.
pub const CONSTANT_WITHOUT_VALUE: Code = Code(32);
/// E0033: RETAIN variable holding references.
pub const RETAIN_REFERENCE: Code = Code(33);
/// E0034: invalid shared variable.
pub const SHARED_VARIABLE: Code = Code(34);
/// E0035: located variable not allowed here.
pub const LOCATED_NOT_ALLOWED: Code = Code(35);
/// E0036: invalid direct address.
pub const DIRECT_ADDRESS: Code = Code(36);
/// E0037: invalid task declaration.
pub const TASK_DECLARATION: Code = Code(37);
/// E0038: task or program instance declared twice.
pub const DUPLICATE_CONFIGURATION_NAME: Code = Code(38);
/// E0039: several configurations.
pub const ONE_CONFIGURATION: Code = Code(39);
/// E0040: unknown program.
pub const UNKNOWN_PROGRAM: Code = Code(40);
/// E0041: unknown task.
pub const UNKNOWN_TASK: Code = Code(41);
/// E0042: no program to run.
pub const PROGRAM_SELECTION: Code = Code(42);
/// E0043: malformed initial value.
pub const INITIAL_VALUE_SHAPE: Code = Code(43);
/// E0044: string initial value must be a literal.
pub const STRING_INITIAL_VALUE: Code = Code(44);
/// E0045: unknown member in initial value.
pub const INITIAL_VALUE_MEMBER: Code = Code(45);
/// E0046: reference with an initial value.
pub const REFERENCE_INITIAL_VALUE: Code = Code(46);
/// E0047: constant does not fit the type.
pub const VALUE_OUT_OF_RANGE: Code = Code(47);
/// E0048: initial value of the wrong type.
pub const INITIAL_VALUE_TYPE: Code = Code(48);
/// E0049: unknown variable.
pub const UNKNOWN_VARIABLE: Code = Code(49);
/// E0050: no such member.
pub const NO_SUCH_MEMBER: Code = Code(50);
/// E0051: wrong indexing.
pub const NOT_AN_ARRAY: Code = Code(51);
/// E0052: constant index out of bounds.
pub const INDEX_OUT_OF_BOUNDS: Code = Code(52);
/// E0053: array index is not an integer.
pub const INDEX_NOT_INTEGER: Code = Code(53);
/// E0054: variable expected.
pub const EXPECTED_VARIABLE: Code = Code(54);
/// E0055: invalid partial access.
pub const PARTIAL_ACCESS: Code = Code(55);
/// E0056: VAR_EXTERNAL does not match a global.
pub const VAR_EXTERNAL: Code = Code(56);
/// E0057: unknown enumeration value.
pub const UNKNOWN_ENUMERATION_VALUE: Code = Code(57);
/// E0058: type mismatch.
pub const TYPE_MISMATCH: Code = Code(58);
/// E0059: implicit narrowing conversion.
pub const IMPLICIT_CONVERSION: Code = Code(59);
/// E0060: operator not applicable to these types.
pub const OPERATOR_TYPES: Code = Code(60);
/// E0061: character used as a number.
pub const CHARACTER_IS_NO_NUMBER: Code = Code(61);
/// E0062: no such conversion.
pub const NO_CONVERSION: Code = Code(62);
/// E0063: arguments of incompatible types.
pub const INCOMPATIBLE_ARGUMENTS: Code = Code(63);
/// E0064: assignment to a read-only variable.
pub const ASSIGN_TO_READ_ONLY: Code = Code(64);
/// E0065: cannot assign.
pub const ASSIGN_TYPE: Code = Code(65);
/// E0066: function block instances cannot be assigned.
pub const ASSIGN_FB_INSTANCE: Code = Code(66);
/// E0067: `REF=` needs a REFERENCE TO.
pub const REF_ASSIGN_TARGET: Code = Code(67);
/// E0068: EXIT outside of a loop.
pub const EXIT_OUTSIDE_LOOP: Code = Code(68);
/// E0069: invalid CASE selector.
pub const CASE_SELECTOR: Code = Code(69);
/// E0070: invalid CASE label.
pub const CASE_LABEL: Code = Code(70);
/// E0071: invalid FOR control variable.
pub const FOR_VARIABLE: Code = Code(71);
/// E0072: FOR step is zero.
pub const FOR_STEP_ZERO: Code = Code(72);
/// E0073: invalid exception variable.
pub const EXCEPTION_VARIABLE: Code = Code(73);
/// E0074: recursive call.
pub const RECURSION: Code = Code(74);
/// E0075: unknown function.
pub const UNKNOWN_FUNCTION: Code = Code(75);
/// E0076: not callable.
pub const NOT_CALLABLE: Code = Code(76);
/// E0077: unknown parameter.
pub const UNKNOWN_PARAMETER: Code = Code(77);
/// E0078: positional after named argument.
pub const ARGUMENT_ORDER: Code = Code(78);
/// E0079: wrong number of arguments.
pub const ARGUMENT_COUNT: Code = Code(79);
/// E0080: argument given twice.
pub const DUPLICATE_ARGUMENT: Code = Code(80);
/// E0081: missing argument.
pub const MISSING_ARGUMENT: Code = Code(81);
/// E0082: invalid VAR_IN_OUT argument.
pub const IN_OUT_ARGUMENT: Code = Code(82);
/// E0083: unsupported output target.
pub const OUTPUT_TARGET: Code = Code(83);
/// E0084: invalid operand of REF() or ADR().
pub const REF_OPERAND: Code = Code(84);
/// E0085: NULL dereferenced.
pub const NULL_DEREFERENCE: Code = Code(85);
/// E0086: `^` applied to a non-reference.
pub const DEREFERENCE_NON_REFERENCE: Code = Code(86);
/// E0087: invalid pointer arithmetic.
pub const POINTER_ARITHMETIC: Code = Code(87);
/// E0088: invalid reference comparison.
pub const REFERENCE_COMPARISON: Code = Code(88);
/// E0089: invalid reference conversion.
pub const REFERENCE_CONVERSION: Code = Code(89);
/// E0090: reference outlives its target.
pub const REFERENCE_ESCAPE: Code = Code(90);
/// E0091: unknown POU.
pub const UNKNOWN_POU: Code = Code(91);
/// E0092: invalid EXTENDS.
pub const INVALID_EXTENDS: Code = Code(92);
/// E0093: ABSTRACT used as concrete.
pub const ABSTRACT_INSTANCE: Code = Code(93);
/// E0094: unknown interface.
pub const UNKNOWN_INTERFACE: Code = Code(94);
/// E0095: interface extends itself.
pub const INTERFACE_CYCLE: Code = Code(95);
/// E0096: too many dynamically called methods.
pub const TOO_MANY_DYNAMIC_METHODS: Code = Code(96);
/// E0097: FINAL method overridden.
pub const FINAL_OVERRIDE: Code = Code(97);
/// E0098: signature differs from the overridden or interface method.
pub const SIGNATURE_MISMATCH: Code = Code(98);
/// E0099: method not implemented.
pub const MISSING_IMPLEMENTATION: Code = Code(99);
/// E0100: ABSTRACT method in a non-ABSTRACT block.
pub const ABSTRACT_METHOD_OWNER: Code = Code(100);
/// E0101: THIS or SUPER without an instance.
pub const NO_INSTANCE: Code = Code(101);
/// E0102: member not accessible.
pub const ACCESS_DENIED: Code = Code(102);
/// E0103: unknown method.
pub const UNKNOWN_METHOD: Code = Code(103);
/// E0104: property cannot be read or written.
pub const PROPERTY_ACCESS: Code = Code(104);
/// E0105: too many program instances.
pub const TOO_MANY_PROGRAM_INSTANCES: Code = Code(105);
/// E0106: data memory exceeded.
pub const DATA_MEMORY_EXCEEDED: Code = Code(106);
/// E0107: internal compiler error.
pub const INTERNAL_ERROR: Code = Code(107);

/// Every code, in order (entry `i` is code `i + 1`).
pub static TABLE: &[Entry] = &[
    Entry {
        code: UNTERMINATED_COMMENT,
        title: "unterminated comment or pragma",
        explanation: "A comment (`(* ... *)` or `/* ... */`) or a pragma (`{ ... }`) was opened but the file ends before it is closed. Everything after the opening is swallowed, so the rest of the file is not compiled. Close the comment with `*)` or `*/`, or the pragma with `}`. Comments nest: each `(*` (or `/*`) inside a comment needs its own `*)` (or `*/`).",
    },
    Entry {
        code: UNTERMINATED_STRING,
        title: "unterminated string literal",
        explanation: "A string literal (`'...'` for STRING, `\"...\"` for WSTRING) is not closed on the same line. Strings cannot span lines; write a line break as `$N` or `$L` inside the literal, and a quote character as `$'` (STRING) or `$\"` (WSTRING).",
    },
    Entry {
        code: INVALID_ESCAPE,
        title: "invalid escape sequence",
        explanation: "Inside a string literal the `$` character starts an escape: `$$`, `$'`, `$\"`, `$L`, `$N`, `$P`, `$R`, `$T`, or two hexadecimal digits (four in a WSTRING) giving a character code. Any other character after `$` is rejected. Write a literal dollar sign as `$$`.",
    },
    Entry {
        code: INVALID_BASED_LITERAL,
        title: "invalid based integer literal",
        explanation: "A based integer literal is written `BASE#DIGITS` with base 2, 8 or 16 (`2#1010`, `8#17`, `16#FF`), and its digits must be valid in that base (underscores may separate digits). Another base, an empty digit sequence or a digit too large for the base is reported here.",
    },
    Entry {
        code: INTEGER_TOO_LARGE,
        title: "integer literal too large",
        explanation: "An integer literal does not fit in 64 bits, the widest integer the compiler handles (LINT, ULINT, LWORD). Use a smaller value, or a REAL/LREAL literal if an approximate value is acceptable.",
    },
    Entry {
        code: MALFORMED_LITERAL,
        title: "malformed typed or date/time literal",
        explanation: "A typed or date/time literal does not have the form its prefix requires: `D#2024-02-29`, `TOD#13:05:00.25`, `DT#2024-02-29-13:05:00`, `BOOL#TRUE`, `REAL#1.5` and so on, with valid field values (month 1 to 12, a day that exists in that month, hour below 24, ...). The message names the literal kind and an example of the expected form.",
    },
    Entry {
        code: MALFORMED_DURATION,
        title: "malformed duration literal",
        explanation: "A duration literal (`T#`, `TIME#`, `LT#`, `LTIME#`) is a sequence of numbers each followed by a unit: `d`, `h`, `m`, `s`, `ms`, `us`, `ns` (`T#1h30m`, `T#1.5s`, `T#-250ms`). An unknown unit, a missing number or unit, or a value that does not fit a 64-bit count of nanoseconds is reported here.",
    },
    Entry {
        code: UNEXPECTED_CHARACTER,
        title: "unexpected character",
        explanation: "The source contains a character that starts no token of Structured Text (for example `?`, `!` or a non-ASCII letter outside a string or comment). Remove it, or put it inside a string literal or a comment.",
    },
    Entry {
        code: SYNTAX,
        title: "syntax error",
        explanation: "The parser expected a particular token or construct (named in the message) and found something else: a missing `;` after a statement, a missing `END_IF`, `THEN` or `:=`, an expression missing its operand, and so on. The parser resynchronises at the next statement, declaration or POU boundary, so later errors may be consequences of this one; fix the first one first.",
    },
    Entry {
        code: NESTED_TOO_DEEPLY,
        title: "nested too deeply",
        explanation: "Expressions, statements or types are nested more deeply than the compiler accepts. The limit keeps every input from overflowing the compiler's stack and is far above what hand-written code needs; split the construct using intermediate variables or functions.",
    },
    Entry {
        code: MISPLACED_POU_ELEMENT,
        title: "element not allowed in this kind of POU",
        explanation: "A POU contains an element its kind does not allow: only a FUNCTION_BLOCK can `EXTENDS` (one) function block or `IMPLEMENTS` interfaces, methods and actions belong to a FUNCTION_BLOCK or a PROGRAM (not to a FUNCTION), a CLASS has no body of its own, and an ACTION written outside its POU is named `ACTION Pou.Action`. Move the element to a POU of the right kind.",
    },
    Entry {
        code: INTERFACE_CONTENT,
        title: "interface content",
        explanation: "An INTERFACE only declares methods and properties: their names, parameters (VAR_INPUT, VAR_OUTPUT, VAR_IN_OUT) and result types. It has no variables, and its methods and properties have no bodies; the function blocks that implement the interface provide those.",
    },
    Entry {
        code: PROPERTY_WITHOUT_ACCESSOR,
        title: "property without accessor",
        explanation: "A PROPERTY must have a GET accessor (to be read), a SET accessor (to be written), or both. A property with neither cannot be used at all.",
    },
    Entry {
        code: SAFE_ATTRIBUTE,
        title: "misused attribute 'safe'",
        explanation: "The pragma `{attribute 'safe' := 'VALUE'}` gives a located output (`AT %Q...`) the value the runtime writes when a task faults and the outputs go safe. It must stand right before such a declaration, must have a value, and the value must be a literal of the output's type that fits its width.",
    },
    Entry {
        code: SHARED_ATTRIBUTE,
        title: "misused attribute 'shared'",
        explanation: "The pragma `{attribute 'shared' := 'write'}` (this project writes the variable), `'read'` (this project reads it from another project) or `'valid'` (a BOOL telling whether the read ones are a fresh copy) marks a global variable shared between projects. It needs one of these three values and applies only to declarations in VAR_GLOBAL.",
    },
    Entry {
        code: UNKNOWN_TASK_PROPERTY,
        title: "unknown task property",
        explanation: "A TASK declaration in a CONFIGURATION takes the properties INTERVAL (a TIME literal: cyclic task), SINGLE (a global BOOL: event task on its rising edge) and PRIORITY (a non-negative integer). Any other name is rejected.",
    },
    Entry {
        code: DUPLICATE_DEFINITION,
        title: "name defined twice",
        explanation: "Two data types, or two POUs (functions, function blocks, programs, classes, interfaces), or a type and a POU, have the same name in the same namespace. Names are case-insensitive. Rename one of them or put them in different namespaces.",
    },
    Entry {
        code: DUPLICATE_VARIABLE,
        title: "variable declared twice",
        explanation: "A variable, parameter, global or member name is declared twice in the same scope, or a function block declares a variable that its base function block (`EXTENDS`) already has, or a method or property takes a name already used by a member. Names are case-insensitive. Rename one of them.",
    },
    Entry {
        code: DUPLICATE_MEMBER,
        title: "duplicate structure member or enumeration value",
        explanation: "A STRUCT declares two members with the same name, or an enumeration declares the same value name twice. Names are case-insensitive.",
    },
    Entry {
        code: RECURSIVE_TYPE,
        title: "type defined in terms of itself",
        explanation: "A data type refers to itself (directly or through other types), or a function block contains an instance of itself or extends itself, so its size would be infinite. Break the cycle, typically with a REF_TO.",
    },
    Entry {
        code: UNKNOWN_TYPE,
        title: "unknown type",
        explanation: "A declaration or a typed literal names a type that is neither an elementary type, nor a TYPE declared in the project, nor a function block, or names something that is not a type (a function, a program). Check the spelling and that the file declaring it is part of the compilation.",
    },
    Entry {
        code: AMBIGUOUS_NAME,
        title: "ambiguous name",
        explanation: "The name is declared in several namespaces that are all visible here (through USING or the global namespace), so the compiler cannot tell which one is meant. Qualify it with its namespace: `Lib.Name`.",
    },
    Entry {
        code: NOT_CONSTANT,
        title: "constant expression required",
        explanation: "The place requires a value known at compile time (an array bound, a string length, an enumeration value, an initial value): a literal, a CONSTANT variable, an enumeration value, or an expression of them. Variables and function calls are not allowed there.",
    },
    Entry {
        code: STRING_LENGTH,
        title: "invalid string length",
        explanation: "The declared length of a STRING must be between 1 and 65000 characters, that of a WSTRING between 1 and 32000.",
    },
    Entry {
        code: ARRAY_BOUNDS,
        title: "invalid array bounds",
        explanation: "Each dimension of an ARRAY is declared `lower..upper` with constant integer bounds and `upper >= lower`, and the whole array must fit in the VM's data memory.",
    },
    Entry {
        code: INVALID_SUBRANGE,
        title: "invalid subrange",
        explanation: "A subrange type `INT(lo..hi)` must have an integer base type, bounds within the range of that type, and a lower bound not above the upper bound.",
    },
    Entry {
        code: REFERENCE_TO_REFERENCE,
        title: "reference to a reference",
        explanation: "A `REFERENCE TO` variable is an alias of another variable and cannot itself refer to a reference. Declare it as a reference to the referenced type instead, or use `REF_TO` for a pointer that can be stored and moved.",
    },
    Entry {
        code: ANONYMOUS_TYPE,
        title: "anonymous enumeration or structure",
        explanation: "Enumerations `(A, B, C)` and structures `STRUCT ... END_STRUCT` must be declared with a name in a TYPE block; they cannot be written inline in a variable declaration. Declare `TYPE Color : (Red, Green); END_TYPE` and use `Color`.",
    },
    Entry {
        code: FB_INSTANCE_NOT_ALLOWED,
        title: "function block instance not allowed here",
        explanation: "Function block instances keep state between calls, so they cannot live where that state would be lost or copied: as structure members, as a FUNCTION's result, or in the variables of a FUNCTION or a METHOD. Declare the instance in a FUNCTION_BLOCK or PROGRAM and pass it as VAR_IN_OUT if needed.",
    },
    Entry {
        code: VAR_BLOCK_NOT_ALLOWED,
        title: "variable block not allowed in this POU",
        explanation: "The POU kind does not allow this kind of VAR block: a PROGRAM has no VAR_IN_OUT (nothing calls it with arguments), a FUNCTION has no VAR_GLOBAL or VAR_EXTERNAL, and VAR_GLOBAL belongs at the top level (or in a PROGRAM), not inside a FUNCTION_BLOCK, METHOD or FUNCTION. Move the variables to an allowed block.",
    },
    Entry {
        code: INOUT_INITIAL_VALUE,
        title: "VAR_IN_OUT with an initial value",
        explanation: "A VAR_IN_OUT parameter is an alias of the caller's variable, so it has no storage of its own to initialise. Remove the initial value.",
    },
    Entry {
        code: CONSTANT_WITHOUT_VALUE,
        title: "constant without a value",
        explanation: "A variable in a `VAR CONSTANT` or `VAR_GLOBAL CONSTANT` block cannot be assigned, so it needs an initial value in its declaration.",
    },
    Entry {
        code: RETAIN_REFERENCE,
        title: "RETAIN variable holding references",
        explanation: "A RETAIN variable keeps its value across a restart, possibly after a new version of the program was downloaded. References and interface values name variables of the build that stored them, which the new build may not have at the same address, so they cannot be retained. Keep the reference in a non-RETAIN variable and re-assign it after a restart.",
    },
    Entry {
        code: SHARED_VARIABLE,
        title: "invalid shared variable",
        explanation: "A global shared between projects (`{attribute 'shared'}`) must have an elementary type (BOOL, integers, REAL, LREAL, bit strings, date and time types, CHAR, WCHAR), cannot be located (`AT %...`), and cannot be a CONSTANT that is read from another project. A program has at most one validity flag (`'valid'`), and it must be a BOOL.",
    },
    Entry {
        code: LOCATED_NOT_ALLOWED,
        title: "located variable not allowed here",
        explanation: "A located variable (`AT %IX0.0`, `AT %QW4`) is mapped to the process image, which exists once: it may be declared only in a PROGRAM's VAR block or in VAR_GLOBAL, and one direct address locates exactly one variable.",
    },
    Entry {
        code: DIRECT_ADDRESS,
        title: "invalid direct address",
        explanation: "A direct address is `%` followed by the area (I, Q, M), the size (X, B, W, D, L; X if omitted) and the position (`%IX0.3`, `%QB2`, `%MD10`). The message says what is wrong, or that the variable's type does not have the width of the address: a bit address needs a BOOL, a byte address a one-byte type, and so on.",
    },
    Entry {
        code: TASK_DECLARATION,
        title: "invalid task declaration",
        explanation: "A TASK needs INTERVAL (a positive TIME literal such as T#10ms) or SINGLE (the name of a global BOOL variable whose rising edge triggers it), and its PRIORITY, if given, must be a non-negative integer.",
    },
    Entry {
        code: DUPLICATE_CONFIGURATION_NAME,
        title: "task or program instance declared twice",
        explanation: "Within a CONFIGURATION each TASK name and each program instance name must be unique.",
    },
    Entry {
        code: ONE_CONFIGURATION,
        title: "several configurations",
        explanation: "A project has at most one CONFIGURATION: it defines the tasks and program instances of the one runtime the image is loaded into. Merge the configurations, or compile them as separate projects.",
    },
    Entry {
        code: UNKNOWN_PROGRAM,
        title: "unknown program",
        explanation: "A program instance in the CONFIGURATION, or the `--program` option, names a PROGRAM that the project does not declare. Check the spelling and that the file declaring the PROGRAM is part of the compilation.",
    },
    Entry {
        code: UNKNOWN_TASK,
        title: "unknown task",
        explanation: "A program instance is attached (`WITH Task`) to a task that the CONFIGURATION does not declare.",
    },
    Entry {
        code: PROGRAM_SELECTION,
        title: "no program to run",
        explanation: "Without a CONFIGURATION, the compiled image runs one PROGRAM every cycle. The project declares none, or several; declare a PROGRAM or a CONFIGURATION, or choose the program with `--program NAME`. Libraries without a program are checked with `plcc check --library`.",
    },
    Entry {
        code: INITIAL_VALUE_SHAPE,
        title: "malformed initial value",
        explanation: "An initial value does not have the shape of the variable's type: an array is initialised with `[v1, v2, n(v)]` and no more elements than it has, a structure with `(member := value, ...)`, a function block instance with `(input := value, ...)`, and an elementary variable with a single value (not an aggregate).",
    },
    Entry {
        code: STRING_INITIAL_VALUE,
        title: "string initial value must be a literal",
        explanation: "A STRING variable is initialised with a STRING literal (`'text'`), a WSTRING variable with a WSTRING literal (`\"text\"`). Other expressions, including constants of another string type, are not accepted as initial values.",
    },
    Entry {
        code: INITIAL_VALUE_MEMBER,
        title: "unknown member in initial value",
        explanation: "A structure or function block initial value `(name := value, ...)` names a member that the structure or function block does not have.",
    },
    Entry {
        code: REFERENCE_INITIAL_VALUE,
        title: "reference with an initial value",
        explanation: "A reference or interface variable can only start as NULL, since the addresses of variables are not constants of the declaration. Assign `REF(x)` (or `ADR(x)`) in the program's code.",
    },
    Entry {
        code: VALUE_OUT_OF_RANGE,
        title: "constant does not fit the type",
        explanation: "A constant (a literal, a constant expression, or a character literal) is outside the range of the type it is used as, for example `300` as a SINT or a USINT, or a negative value as an unsigned type. Use a wider type or a value in range.",
    },
    Entry {
        code: INITIAL_VALUE_TYPE,
        title: "initial value of the wrong type",
        explanation: "The initial value in a declaration is not of the variable's type and cannot be converted to it implicitly, for example a REAL literal for an INT, or TRUE for a TIME.",
    },
    Entry {
        code: UNKNOWN_VARIABLE,
        title: "unknown variable",
        explanation: "The name is not a variable of the POU (its VAR blocks and parameters), not a global variable, not an enumeration value and not a constant visible here. Check the spelling (names are case-insensitive), declare the variable, or declare a VAR_EXTERNAL for a global of another file.",
    },
    Entry {
        code: NO_SUCH_MEMBER,
        title: "no such member",
        explanation: "The `.name` selector names a member that the value does not have: a structure member that is not declared, a variable of a function block instance that is not an input or output (internal variables are private), or a member of a value that has none (an integer, a STRING).",
    },
    Entry {
        code: NOT_AN_ARRAY,
        title: "wrong indexing",
        explanation: "An index `[i]` was applied to something that is not an array, or with a number of indexes different from the array's number of dimensions (`a[i, j]` for a two-dimensional array).",
    },
    Entry {
        code: INDEX_OUT_OF_BOUNDS,
        title: "constant index out of bounds",
        explanation: "A constant array index lies outside the bounds declared for that dimension. Computed indexes are checked at run time (the task traps); constant ones are rejected at compile time.",
    },
    Entry {
        code: INDEX_NOT_INTEGER,
        title: "array index is not an integer",
        explanation: "An array index must be an integer expression (any of SINT to ULINT, or BYTE to LWORD). Convert REAL values explicitly, for example with REAL_TO_DINT.",
    },
    Entry {
        code: EXPECTED_VARIABLE,
        title: "variable expected",
        explanation: "The construct needs a variable (something with an address that can be read and written): the target of an assignment, an output connection, a VAR_IN_OUT argument, an operand of REF(). An expression such as `a + 1` or a function call is not a variable.",
    },
    Entry {
        code: PARTIAL_ACCESS,
        title: "invalid partial access",
        explanation: "A partial access selects a bit (`x.3`, `x.%X3`), byte (`x.%B1`), word (`x.%W1`) or double word (`x.%D0`) of a bit-string or integer variable. It needs such a variable, and the index must lie within it: bits 0..15 of a WORD, bytes 0..3 of a DWORD, and so on.",
    },
    Entry {
        code: VAR_EXTERNAL,
        title: "VAR_EXTERNAL does not match a global",
        explanation: "A VAR_EXTERNAL declaration refers to a VAR_GLOBAL of the same name, which must exist and have the same type.",
    },
    Entry {
        code: UNKNOWN_ENUMERATION_VALUE,
        title: "unknown enumeration value",
        explanation: "A qualified enumeration value `Type#Value` names a value that the enumeration type does not declare.",
    },
    Entry {
        code: TYPE_MISMATCH,
        title: "type mismatch",
        explanation: "An expression has a type that the context does not accept, and no implicit conversion exists: a condition that is not BOOL, an argument or output of the wrong type, a value of an enumeration for another enumeration, a STRING where a number is expected. The message gives the expected and the found types.",
    },
    Entry {
        code: IMPLICIT_CONVERSION,
        title: "implicit narrowing conversion",
        explanation: "IEC 61131-3 converts implicitly only where no value can be lost: a narrower integer to a wider one of the same signedness (or an unsigned one to a wider signed one), an integer to REAL/LREAL when it fits exactly, REAL to LREAL. Anything else needs an explicit conversion function, which the message names (for example DINT_TO_INT); the compiler does not truncate silently.",
    },
    Entry {
        code: OPERATOR_TYPES,
        title: "operator not applicable to these types",
        explanation: "The operator is not defined for the operand types: arithmetic needs numbers (or TIME and date values in the combinations the standard defines), AND/OR/XOR/NOT need BOOL or bit strings, strings can only be compared, and both operands of a binary operator must have a common type. Convert an operand explicitly if that is what is meant.",
    },
    Entry {
        code: CHARACTER_IS_NO_NUMBER,
        title: "character used as a number",
        explanation: "CHAR and WCHAR values are characters, not numbers: they can be compared with other characters (`c = CHAR#'a'`), but mixing them with integers in arithmetic or comparisons needs a conversion such as CHAR_TO_BYTE.",
    },
    Entry {
        code: NO_CONVERSION,
        title: "no such conversion",
        explanation: "The conversion function `X_TO_Y` names two types between which no conversion is defined (for example from a TIME to a STRING of another kind, or between unrelated structured types).",
    },
    Entry {
        code: INCOMPATIBLE_ARGUMENTS,
        title: "arguments of incompatible types",
        explanation: "A standard function that takes several arguments of one generic type (MAX, MIN, LIMIT, SEL, MUX, comparison functions, ...) received arguments with no common type, or of a type it does not accept (MAX and MIN need numbers, TIME or enumeration values).",
    },
    Entry {
        code: ASSIGN_TO_READ_ONLY,
        title: "assignment to a read-only variable",
        explanation: "The target of the assignment or output connection cannot be written: a CONSTANT, or an input of another POU's instance (set it through the call, `fb(IN := ...)`).",
    },
    Entry {
        code: ASSIGN_TYPE,
        title: "cannot assign",
        explanation: "The value cannot be assigned to the target: the types differ and no implicit conversion applies, or the target is an array or a structure and the value is of another array or structure type. The message may hint at the explicit conversion.",
    },
    Entry {
        code: ASSIGN_FB_INSTANCE,
        title: "function block instances cannot be assigned",
        explanation: "A function block instance carries state and identity and cannot be copied by assignment. Assign its inputs and outputs individually, or use a reference (REF_TO) or an interface to refer to the instance.",
    },
    Entry {
        code: REF_ASSIGN_TARGET,
        title: "`REF=` needs a REFERENCE TO",
        explanation: "The `REF=` assignment binds a `REFERENCE TO` variable to another variable. Its target must be declared `REFERENCE TO`; for a `REF_TO` pointer write `p := REF(x)`.",
    },
    Entry {
        code: EXIT_OUTSIDE_LOOP,
        title: "EXIT outside of a loop",
        explanation: "EXIT leaves the innermost FOR, WHILE or REPEAT loop, so it can only appear inside one. Use RETURN to leave the POU.",
    },
    Entry {
        code: CASE_SELECTOR,
        title: "invalid CASE selector",
        explanation: "The selector of a CASE statement must be an integer, bit string or enumeration value; its labels are compared with it. REAL, STRING and structured selectors are not allowed.",
    },
    Entry {
        code: CASE_LABEL,
        title: "invalid CASE label",
        explanation: "A CASE label must be a constant integer or enumeration value, or a range `lo..hi` with `lo <= hi`, and no value may appear in two labels, since only one branch of a CASE runs.",
    },
    Entry {
        code: FOR_VARIABLE,
        title: "invalid FOR control variable",
        explanation: "The control variable of a FOR loop must be a plain local or global integer variable (not an array element, a member, a partial access or a reference dereference).",
    },
    Entry {
        code: FOR_STEP_ZERO,
        title: "FOR step is zero",
        explanation: "A FOR loop with `BY 0` never reaches its end value. Use a non-zero step, or a WHILE loop.",
    },
    Entry {
        code: EXCEPTION_VARIABLE,
        title: "invalid exception variable",
        explanation: "The variable named in `__CATCH(e)` receives the trap code and must be declared `: __EXCEPTION` (or an integer type).",
    },
    Entry {
        code: RECURSION,
        title: "recursive call",
        explanation: "IEC 61131-3 forbids recursion: a POU must not call itself, directly or through other POUs, since the VM gives each function a fixed frame. Rewrite the algorithm with a loop.",
    },
    Entry {
        code: UNKNOWN_FUNCTION,
        title: "unknown function",
        explanation: "The called name is not a FUNCTION of the project, a standard function, a conversion function, a function block instance, a method or an action. Check the spelling and that the file declaring it is part of the compilation.",
    },
    Entry {
        code: NOT_CALLABLE,
        title: "not callable",
        explanation: "The name in a call is not something that can be called: a type (call an instance of a function block type, not the type), a CLASS (call its methods), or a variable that is neither a function block instance nor a reference to one.",
    },
    Entry {
        code: UNKNOWN_PARAMETER,
        title: "unknown parameter",
        explanation: "A named argument (`name := value` or `name => target`) names a parameter that the called POU or standard function does not have, or connects an input with `=>` (outputs use `=>`, inputs `:=`). The message lists the parameters where it can.",
    },
    Entry {
        code: ARGUMENT_ORDER,
        title: "positional after named argument",
        explanation: "In a call, positional arguments (`F(a, b)`) come first and named ones (`F(IN := a)`) after them; once a named argument appears, the positions of the following ones are no longer defined.",
    },
    Entry {
        code: ARGUMENT_COUNT,
        title: "wrong number of arguments",
        explanation: "The call passes more (or fewer) arguments than the function, standard function or action takes. Extensible standard functions (ADD, MAX, CONCAT, MUX, ...) need at least the number the message names; actions take none.",
    },
    Entry {
        code: DUPLICATE_ARGUMENT,
        title: "argument given twice",
        explanation: "The same parameter is given twice in one call, by name or once by position and once by name.",
    },
    Entry {
        code: MISSING_ARGUMENT,
        title: "missing argument",
        explanation: "The call omits an argument that cannot be defaulted: a VAR_IN_OUT parameter (it must be connected to a variable on every call) or a required input of a standard function.",
    },
    Entry {
        code: IN_OUT_ARGUMENT,
        title: "invalid VAR_IN_OUT argument",
        explanation: "A VAR_IN_OUT parameter is an alias of the caller's variable, so its argument must be a variable (not an expression or a partial access such as `x.3`) of exactly the parameter's type: no conversion takes place.",
    },
    Entry {
        code: OUTPUT_TARGET,
        title: "unsupported output target",
        explanation: "An output connection `out => target` needs a target that can receive the output's value: the output of an element of a function block array cannot go to an array element with a computed index (use a temporary variable), and an integer output of a standard function block cannot go to a variable of another type.",
    },
    Entry {
        code: REF_OPERAND,
        title: "invalid operand of REF() or ADR()",
        explanation: "REF() and ADR() take the address of a variable; __ISVALIDREF tests a reference or an interface. The address of a whole array of function block instances, or a byte pointer to the text of a STRING that is not a plain variable or parameter, cannot be taken; take the address of one element or of the STRING variable itself.",
    },
    Entry {
        code: NULL_DEREFERENCE,
        title: "NULL dereferenced",
        explanation: "`NULL^` dereferences a reference known to be NULL, which would always trap. Dereference a reference variable, checked with __ISVALIDREF if it may be NULL.",
    },
    Entry {
        code: DEREFERENCE_NON_REFERENCE,
        title: "`^` applied to a non-reference",
        explanation: "The dereference operator `^` applies to a reference (REF_TO, POINTER TO) only; the value it was applied to is of another type.",
    },
    Entry {
        code: POINTER_ARITHMETIC,
        title: "invalid pointer arithmetic",
        explanation: "References allow adding or subtracting an integer number of bytes, the difference of two references, and comparisons; no other operator. A reference to data that itself holds references or function block instances cannot be moved, since the moved reference could reach them as plain bytes.",
    },
    Entry {
        code: REFERENCE_COMPARISON,
        title: "invalid reference comparison",
        explanation: "A reference can be compared with another reference, an interface value, NULL or an integer address; comparing it with other values (a REAL, a STRING, a structure) is meaningless.",
    },
    Entry {
        code: REFERENCE_CONVERSION,
        title: "invalid reference conversion",
        explanation: "References come from REF()/ADR() so that every access through them can be checked; an integer cannot become a reference. A reference to a STRING and a byte pointer are not interchangeable either: STRINGs carry a length header in front of their text. Take REF()/ADR() of the STRING variable where the byte pointer is needed.",
    },
    Entry {
        code: REFERENCE_ESCAPE,
        title: "reference outlives its target",
        explanation: "The reference may point to a temporary variable (a FUNCTION's or METHOD's variables, a VAR_TEMP, or a caller's temporaries reached through a reference parameter), which is re-initialised by the next call. Such a reference may be used and returned during the call, but not stored in a variable that outlives the call (a function block's or program's variable, a global, an output of an instance).",
    },
    Entry {
        code: UNKNOWN_POU,
        title: "unknown POU",
        explanation: "An ACTION, METHOD or PROPERTY written outside its POU (`ACTION Pou.Action`) names a POU that the project does not declare.",
    },
    Entry {
        code: INVALID_EXTENDS,
        title: "invalid EXTENDS",
        explanation: "`EXTENDS Base` must name a function block (or class) of the project that is not FINAL.",
    },
    Entry {
        code: ABSTRACT_INSTANCE,
        title: "ABSTRACT used as concrete",
        explanation: "An ABSTRACT function block or method has no complete implementation: the block cannot be instantiated (declare an instance of a block derived from it) and an ABSTRACT method cannot be called through SUPER^ or directly on its own block.",
    },
    Entry {
        code: UNKNOWN_INTERFACE,
        title: "unknown interface",
        explanation: "`IMPLEMENTS` or an interface's `EXTENDS` names an interface that the project does not declare.",
    },
    Entry {
        code: INTERFACE_CYCLE,
        title: "interface extends itself",
        explanation: "An interface extends itself, directly or through other interfaces. Interface inheritance must be acyclic.",
    },
    Entry {
        code: TOO_MANY_DYNAMIC_METHODS,
        title: "too many dynamically called methods",
        explanation: "The methods that can be called through interfaces or overriding (dynamic dispatch) are numbered in the image, and there are more than the image format can number. Reduce the number of distinct overridden or interface methods.",
    },
    Entry {
        code: FINAL_OVERRIDE,
        title: "FINAL method overridden",
        explanation: "A method declared FINAL in a base function block cannot be redefined in a derived one.",
    },
    Entry {
        code: SIGNATURE_MISMATCH,
        title: "signature differs from the overridden or interface method",
        explanation: "A method that overrides a base method, or implements an interface method, must have the same signature: result type, and the names, kinds (input, output, in-out) and types of its parameters, in the same order.",
    },
    Entry {
        code: MISSING_IMPLEMENTATION,
        title: "method not implemented",
        explanation: "A function block that is not ABSTRACT must implement every ABSTRACT method it inherits and every method and property of the interfaces it implements.",
    },
    Entry {
        code: ABSTRACT_METHOD_OWNER,
        title: "ABSTRACT method in a non-ABSTRACT block",
        explanation: "An ABSTRACT method has no body, so only an ABSTRACT function block may declare one. Declare the block `FUNCTION_BLOCK ABSTRACT Name`, or give the method a body.",
    },
    Entry {
        code: NO_INSTANCE,
        title: "THIS or SUPER without an instance",
        explanation: "THIS refers to the instance a function block's body, method or action runs on, and SUPER to its base block; there is no such instance in a FUNCTION or a PROGRAM's plain code, and no SUPER in a block that extends nothing.",
    },
    Entry {
        code: ACCESS_DENIED,
        title: "member not accessible",
        explanation: "The method or property is PRIVATE (usable only by its own block), PROTECTED (its block and the blocks derived from it) or INTERNAL (its namespace), and is used from outside that scope.",
    },
    Entry {
        code: UNKNOWN_METHOD,
        title: "unknown method",
        explanation: "The called method is not declared by the interface (or the function block) of the value it is called on.",
    },
    Entry {
        code: PROPERTY_ACCESS,
        title: "property cannot be read or written",
        explanation: "A property without a GET accessor cannot be read, one without a SET accessor cannot be written, and a property is not called with arguments.",
    },
    Entry {
        code: TOO_MANY_PROGRAM_INSTANCES,
        title: "too many program instances",
        explanation: "The VM runs a bounded number of task records (one per program instance); the CONFIGURATION declares more. Combine programs or instances.",
    },
    Entry {
        code: DATA_MEMORY_EXCEEDED,
        title: "data memory exceeded",
        explanation: "The variables of the program (globals, program instances, function block instances and the frames of the functions) need more data memory than the VM provides. Reduce array sizes or string lengths.",
    },
    Entry {
        code: INTERNAL_ERROR,
        title: "internal compiler error",
        explanation: "The compiler produced an image that the image builder or the VM's verifier rejected. This is a bug in the compiler, not in the program; the verifier keeps such an image from ever running. Please report it with the source that triggers it.",
    },
];

/// The entry of a code written `E0042` (or `e42`, `0042`, `42`).
pub fn lookup(text: &str) -> Option<&'static Entry> {
    let digits = text.trim();
    let digits = digits
        .strip_prefix('E')
        .or_else(|| digits.strip_prefix('e'))
        .unwrap_or(digits);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let n: usize = digits.parse().ok()?;
    TABLE.get(n.checked_sub(1)?)
}

/// The list of all codes as Markdown (the text of `docs/plc-diagnostics.md`).
pub fn markdown() -> String {
    let mut out = String::from(
        "# PLC compiler diagnostics\n\n\
         Every error the Structured Text compiler (`plcc`) reports carries a stable code, \
         printed as `error[E0042]: ...`. `plcc explain E0042` prints the explanation of a code.\n\n\
         This file is generated from the table in \
         `partitions/softplc/compiler/src/codes.rs` by `plcc explain --markdown`; a test \
         checks that the two agree.\n",
    );
    for e in TABLE {
        out.push_str(&format!(
            "\n## {}: {}\n\n{}\n",
            e.code, e.title, e.explanation
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_numbered_in_order() {
        for (i, e) in TABLE.iter().enumerate() {
            assert_eq!(usize::from(e.code.number()), i + 1);
            assert!(!e.title.is_empty() && !e.explanation.is_empty());
        }
    }

    #[test]
    fn lookup_accepts_the_printed_form() {
        assert_eq!(lookup("E0001").map(|e| e.code), Some(Code(1)));
        assert_eq!(lookup("e1").map(|e| e.code), Some(Code(1)));
        assert!(lookup("E9999").is_none());
        assert!(lookup("E0000").is_none());
        assert!(lookup("X12").is_none());
    }
}
