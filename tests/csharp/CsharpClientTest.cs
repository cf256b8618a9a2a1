// Runs under Mono for tests/csharp/csharp_test.py: the package's C# API
// (client/csharp/Runtime) against a gmr-server on loopback. Subscribes to a
// view of MOTION with ROOTS in Unity's conventions (positions, orientations
// and local transforms), writes FRAMES polled frames, asks SetRoots(NEW_ROOTS)
// while it streams and writes FRAMES more, then checks what must be refused.
// Everything it saw goes to OUT as text lines the Python side compares with
// `gmr positions`:
//   skeleton VERSION NAME:PARENT ...
//   frame PHASE INDEX VERSION P(3n) O(4n) LR(4n) LT(3n)     (numbers in "R" form)
//   query JOINTS P(3n per frame) / error STATUS MESSAGE / counts RECEIVED REPLACED
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Text;
using System.Threading;

public static class CsharpClientTest
{
    static string Arg(string[] args, string name)
    {
        int i = Array.IndexOf(args, name);
        return i >= 0 && i + 1 < args.Length ? args[i + 1] : "";
    }

    static string Numbers(double[] values)
    {
        var sb = new StringBuilder();
        foreach (double v in values) sb.Append(' ').Append(v.ToString("R", CultureInfo.InvariantCulture));
        return sb.ToString();
    }

    static void Skeleton(TextWriter w, Gmr.Subscription s)
    {
        var sb = new StringBuilder("skeleton " + s.SkeletonVersion);
        foreach (var j in s.Joints) sb.Append(' ').Append(j.Name).Append(':').Append(j.Parent);
        w.WriteLine(sb.ToString());
    }

    // Polls until `count` frames of the subscription's current skeleton were written.
    static void Frames(TextWriter w, Gmr.Subscription s, string phase, int count)
    {
        int written = 0;
        var deadline = DateTime.UtcNow.AddSeconds(60);
        while (written < count)
        {
            if (DateTime.UtcNow > deadline) throw new TimeoutException(phase + ": " + written + " frames in 60 s");
            if (!s.Poll())
            {
                if (s.Ended) throw new Exception(phase + ": the subscription ended: " + s.EndReason);
                Thread.Sleep(2);
                continue;
            }
            // The skeleton's version is known from the first frame on.
            if (s.SkeletonChanged || (phase == "before" && written == 0)) Skeleton(w, s);
            if (!s.HasLocalTransforms || !s.HasOrientations) throw new Exception("a frame without local transforms or orientations");
            w.WriteLine("frame " + phase + " " + s.FrameIndex + " " + s.SkeletonVersion + Numbers(s.Positions) +
                        Numbers(s.Orientations) + Numbers(s.LocalRotations) + Numbers(s.LocalTranslations));
            written++;
        }
    }

    static void Refused(TextWriter w, string what, Action call)
    {
        try
        {
            call();
            w.WriteLine("error none " + what);
        }
        catch (Gmr.GmrException e)
        {
            w.WriteLine("error " + e.Status + " " + e.Message.Replace('\n', ' '));
        }
    }

    public static int Main(string[] args)
    {
        int port = int.Parse(Arg(args, "--port"));
        string motion = Arg(args, "--motion");
        int frames = int.Parse(Arg(args, "--frames"));
        double mpu = double.Parse(Arg(args, "--mpu"), CultureInfo.InvariantCulture);
        using (var w = new StreamWriter(Arg(args, "--out")))
        using (var client = Gmr.Client.Connect("127.0.0.1", port))
        {
            bool listed = false;
            foreach (var m in client.ListMotions()) listed |= m.Name == motion;
            w.WriteLine("listed " + listed);
            uint view = client.CreateView(motion);
            string roots = Arg(args, "--roots");
            if (roots != "") client.SetRoots(view, roots.Split(','));
            var options = new Gmr.SubscribeOptions
            {
                Conventions = Gmr.Conventions.Unity, LocalTransforms = true, Orientations = true, Loop = true,
                SourceMetresPerUnit = mpu,
            };
            using (var s = client.Subscribe(view, options))
            {
                w.WriteLine("unit " + s.MetresPerUnit.ToString("R", CultureInfo.InvariantCulture));
                Frames(w, s, "before", frames);
                client.SetRoots(view, Arg(args, "--new-roots").Split(','));
                uint before = s.SkeletonVersion;
                // Frames of the old skeleton may still arrive first: skip them.
                var deadline = DateTime.UtcNow.AddSeconds(30);
                while (s.SkeletonVersion == before)
                {
                    if (DateTime.UtcNow > deadline) throw new TimeoutException("no frame of the new skeleton");
                    if (!s.Poll()) Thread.Sleep(2);
                }
                if (!s.SkeletonChanged) throw new Exception("the first frame of a new version did not say the skeleton changed");
                Skeleton(w, s);
                Frames(w, s, "after", frames);
                ulong received, replaced;
                s.Counts(out received, out replaced);
                w.WriteLine("counts " + received + " " + replaced);
                w.WriteLine("latency " + s.LatencyMs().ToString("R", CultureInfo.InvariantCulture));
            }
            // The same view queried: positions of its first frames, Unity's conventions.
            int joints;
            double[] q = client.QueryPositions(view, 0, 3, Gmr.Conventions.Unity, out joints);
            w.WriteLine("query " + joints + Numbers(q));
            // Your character: the motion retargeted onto a rig given line by line
            // ("name parent x y z", centimetres; a joint ending in _End has no channels).
            string rigFile = Arg(args, "--rig");
            if (rigFile != "")
            {
                var rig = new System.Collections.Generic.List<Gmr.RigJoint>();
                foreach (string line in File.ReadAllLines(rigFile))
                {
                    string[] f = line.Split(' ');
                    Func<int, double> at = k => double.Parse(f[k], CultureInfo.InvariantCulture);
                    int parent = int.Parse(f[1]);
                    Gmr.Channel[] channels = f[0].EndsWith("_End") ? new Gmr.Channel[0]
                        : parent < 0 ? new[] { Gmr.Channel.XPosition, Gmr.Channel.YPosition, Gmr.Channel.ZPosition,
                                               Gmr.Channel.ZRotation, Gmr.Channel.XRotation, Gmr.Channel.YRotation }
                        : new[] { Gmr.Channel.ZRotation, Gmr.Channel.XRotation, Gmr.Channel.YRotation };
                    rig.Add(new Gmr.RigJoint(f[0], parent, at(2), at(3), at(4), channels));
                }
                uint onRig = client.CreateView(motion);
                var badMap = new System.Collections.Generic.Dictionary<string, string> { { "left_hand", "LeftPaw" } };
                Refused(w, "a map naming an absent joint", () => client.Retarget(onRig, rig.ToArray(), null, badMap));
                client.Retarget(onRig, rig.ToArray(), metresPerUnit: 0.01);
                double[] r = client.QueryPositions(onRig, 0, 3, Gmr.Conventions.Unity, out joints);
                w.WriteLine("retarget " + joints + Numbers(r));
            }
            Refused(w, "unknown motion", () => client.CreateView("no such motion"));
            Refused(w, "unknown joint", () => client.ShiftRoot(view, "no such joint"));
            Refused(w, "frames past the end", () => client.QueryPositions(view, 1u << 30, (1u << 30) + 1, Gmr.Conventions.Unity, out joints));
        }
        Gmr.Client dead = null;
        try
        {
            dead = Gmr.Client.Connect("127.0.0.1", 1);
        }
        catch (Gmr.GmrException e)
        {
            Console.WriteLine("connect to a closed port: " + e.Status + ": " + e.Message);
            if (e.Status != Gmr.Status.Connection) return 3;
        }
        if (dead != null) return 2;
        return 0;
    }
}
