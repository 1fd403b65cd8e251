//! A Rust std program run unmodified (static, musl) in the Linux guest and on the host,
//! printing the same lines on both (scenario `guest_rust_std`): threads with a shared
//! counter under a `Mutex`, a `Condvar` handshake, `std::sync::mpsc` channels from four
//! producers, a `Barrier`, scoped threads, `std::fs` (create, append, rename, read, list,
//! metadata, remove) in a directory given as the first argument, and a child process.
//! Exit status 0 when every check held.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Barrier, Condvar, Mutex};
use std::thread;

fn threads_and_locks() {
    let counter = Arc::new(Mutex::new(0u64));
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let counter = Arc::clone(&counter);
            thread::spawn(move || {
                for _ in 0..10_000 {
                    *counter.lock().expect("lock") += 1;
                }
            })
        })
        .collect();
    for h in handles {
        h.join().expect("join");
    }
    println!(
        "mutex: 4 threads x 10000 = {}",
        *counter.lock().expect("lock")
    );

    let pair = Arc::new((Mutex::new(false), Condvar::new()));
    let waiter = {
        let pair = Arc::clone(&pair);
        thread::spawn(move || {
            let (ready, signal) = &*pair;
            let mut ready = ready.lock().expect("lock");
            while !*ready {
                ready = signal.wait(ready).expect("wait");
            }
            "woken"
        })
    };
    {
        let (ready, signal) = &*pair;
        *ready.lock().expect("lock") = true;
        signal.notify_one();
    }
    println!("condvar: the waiter was {}", waiter.join().expect("join"));

    let barrier = Arc::new(Barrier::new(3));
    let arrived = Arc::new(AtomicU64::new(0));
    let leaders: usize = (0..3)
        .map(|_| {
            let (barrier, arrived) = (Arc::clone(&barrier), Arc::clone(&arrived));
            thread::spawn(move || {
                arrived.fetch_add(1, Ordering::SeqCst);
                let leader = barrier.wait().is_leader();
                (arrived.load(Ordering::SeqCst), leader)
            })
        })
        .collect::<Vec<_>>()
        .into_iter()
        .map(|h| h.join().expect("join"))
        .map(|(seen, leader)| {
            assert_eq!(seen, 3, "a thread passed the barrier early");
            usize::from(leader)
        })
        .sum();
    println!("barrier: 3 threads passed together, {leaders} leader");

    let id = thread::current().id();
    let named = thread::Builder::new()
        .name("worker".into())
        .spawn(move || {
            (
                thread::current().name().map(str::to_string),
                thread::current().id() != id,
            )
        })
        .expect("spawn")
        .join()
        .expect("join");
    println!("names: {:?}, another thread: {}", named.0, named.1);
}

fn channels() {
    let (tx, rx) = mpsc::channel();
    for producer in 0..4u64 {
        let tx = tx.clone();
        thread::spawn(move || {
            for i in 0..250 {
                tx.send((producer, i)).expect("send");
            }
        });
    }
    drop(tx);
    let mut per_producer = BTreeMap::new();
    let mut sum = 0;
    for (producer, i) in rx {
        *per_producer.entry(producer).or_insert(0) += 1;
        sum += i;
    }
    println!("mpsc: {per_producer:?} sum {sum}");

    let (tx, rx) = mpsc::sync_channel(1);
    let echo = thread::spawn(move || rx.iter().map(|s: String| s.len()).sum::<usize>());
    for word in ["scan", "cycle", "window"] {
        tx.send(word.to_string()).expect("send");
    }
    drop(tx);
    println!("sync_channel: {} bytes", echo.join().expect("join"));

    let mut data = vec![0u32; 1000];
    thread::scope(|s| {
        for (n, chunk) in data.chunks_mut(250).enumerate() {
            s.spawn(move || chunk.iter_mut().for_each(|v| *v = n as u32 + 1));
        }
    });
    println!("scoped: sum {}", data.iter().sum::<u32>());
}

fn files(dir: &std::path::Path) -> std::io::Result<()> {
    let work = dir.join("rust-std-check");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(work.join("sub"))?;
    let first = work.join("first.txt");
    std::fs::write(&first, "line one\n")?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(&first)?
        .write_all(b"line two\n")?;
    let moved = work.join("sub/moved.txt");
    std::fs::rename(&first, &moved)?;
    let mut text = String::new();
    std::fs::File::open(&moved)?.read_to_string(&mut text)?;
    println!("fs: read back {:?}", text);
    println!(
        "fs: {} bytes, file {}, first.txt exists {}",
        std::fs::metadata(&moved)?.len(),
        std::fs::metadata(&moved)?.is_file(),
        first.exists()
    );
    let mut names: Vec<String> = std::fs::read_dir(&work)?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<Result<_, _>>()?;
    names.sort();
    println!("fs: listing {names:?}");
    std::fs::remove_dir_all(&work)?;
    println!("fs: removed, exists {}", work.exists());
    Ok(())
}

fn child() {
    let out = std::process::Command::new("sh")
        .args(["-c", "echo from the child; exit 3"])
        .output()
        .expect("spawn sh");
    println!(
        "child: {:?}, status {:?}",
        String::from_utf8_lossy(&out.stdout).trim(),
        out.status.code()
    );
}

fn main() {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "/tmp".into());
    threads_and_locks();
    channels();
    if let Err(e) = files(std::path::Path::new(&dir)) {
        println!("fs: failed: {e}");
        std::process::exit(1);
    }
    child();
    println!("all checks done");
}
